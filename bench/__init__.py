"""Benchmarks of mrsteer (``mrsteer bench``), installed as ``mrsteer_bench``.

Each benchmark measures a baseline in the same run, so that its ratio means something on a
noisy machine; none of them is a pass/fail test.
"""
