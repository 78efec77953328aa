"""Reading the actuator and sensor model files (``--actuator FILE``, ``--sensors FILE``).

A spec is ``ideal``, ``default`` or a TOML file path; files are read with tomllib, unknown keys
are rejected and every value is range-checked, each error one line naming the key and the
file (as ``scenario`` does for scenario files, with ``ModelFileError`` for ``ScenarioError``).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any


class ModelFileError(ValueError):
    """A model spec or file that cannot be used; the message names the file and the key."""


def read_table(path: str) -> dict[str, Any]:
    """The TOML file at ``path`` as a dict, or a one-line ModelFileError."""
    p = Path(path)
    if not p.is_file():
        raise ModelFileError(f"{path}: no such file (give 'ideal', 'default' or a TOML file)")
    try:
        return tomllib.loads(p.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelFileError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ModelFileError(f"{path}: not valid TOML: {str(exc).splitlines()[0]}") from None


def reject_unknown(data: dict[str, Any], allowed: set[str], where: str) -> None:
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ModelFileError(f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})")


def number(data: dict[str, Any], key: str, default: float, lo: float, hi: float, where: str,
           lo_open: bool = False) -> float:
    """data[key] (or ``default``) as a float in [lo, hi] ((lo, hi] if ``lo_open``); inf allowed if hi is."""
    value = data.get(key, default)
    ok = isinstance(value, int | float) and not isinstance(value, bool) and not math.isnan(value)
    ok = ok and (lo < value if lo_open else lo <= value) and value <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        raise ModelFileError(f"{where}: {key!r} must be a number in {bracket}{lo:g}, {hi:g}], got {value!r}")
    return float(value)


def integer(data: dict[str, Any], key: str, default: int, lo: int, hi: int, where: str) -> int:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ModelFileError(f"{where}: {key!r} must be an integer in [{lo}, {hi}], got {value!r}")
    return value


def boolean(data: dict[str, Any], key: str, default: bool, where: str) -> bool:
    value = data.get(key, default)
    if not isinstance(value, bool):
        raise ModelFileError(f"{where}: {key!r} must be true or false, got {value!r}")
    return value


def table(data: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise ModelFileError(f"{where}: [{key}] must be a table")
    return value
