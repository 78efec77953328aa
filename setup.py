"""The C control cycle's extension (ports/c/cffi_cycle.py), compiled by ``pip install``;
everything else is pyproject.toml's."""

from setuptools import setup

setup(cffi_modules=["ports/c/cffi_cycle.py:ffibuilder"])
