"""Benchmarks of mrsteer (``mrsteer bench``), installed as ``mrsteer_bench``.

Each benchmark measures a baseline in the same run, so that its ratio means something on a
noisy machine; none of them is a pass/fail test.

* ``run``: the command, its options and the table;
* ``micro`` (firmware ``step()``, the receive path; ``timer``), ``offline`` (the sweep),
  ``campaign`` (the batch engine);
* ``loop``: one controller process live on the fallback bus (lateness, missed cycles, latency,
  memory); ``loop_compare``: the Python and the C controller side by side, quiet and under
  ``cpu_load``'s bounded busy loops; ``machine_state``: what the machine was doing meanwhile.
"""
