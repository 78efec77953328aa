"""Calibration files: a ``ControllerConfig`` as ``key = value`` lines (``.cfg``).

One line per field, ``#`` comments, tables as comma-separated numbers (``schedule_k = 10.4,
27.0``), an empty value for an empty table and ``none`` for an unset constant gain.  Numbers are
written with 17 significant digits, so a file read back is the same calibration bit for bit.
Lines starting with ``c.`` (the coefficients that tests/vectors/*.cfg carry for a port to
compare with its own configure()) are ignored.  The C port reads the same format
(``ports/c/mrs_config.c``); ``mrsteer controller --calibration FILE`` and the C node take it.
"""

from __future__ import annotations

import typing
from dataclasses import fields
from pathlib import Path

from firmware_py.calibration import ControllerConfig, validate


class CalibrationError(ValueError):
    """A calibration file that cannot be read; the message names the file, line and key."""


def _text(x: object) -> str:
    if x is None:
        return "none"
    if isinstance(x, tuple):
        return ", ".join(_text(v) for v in x)
    if isinstance(x, float):
        return repr(x)
    return str(x)


def dumps(cfg: ControllerConfig) -> str:
    """The calibration as ``key = value`` lines (every field, in declaration order)."""
    return "".join(f"{f.name} = {_text(getattr(cfg, f.name))}\n" for f in fields(cfg))


def _kinds() -> dict[str, str]:
    hints = typing.get_type_hints(ControllerConfig)
    out = {}
    for name, hint in hints.items():
        text = str(hint)
        out[name] = ("table" if "tuple" in text else "str" if hint is str else "int" if hint is int
                     else "optional" if "None" in text else "float")
    return out


def _value(kind: str, text: str) -> object:
    if kind == "str":
        return text
    if kind == "int":
        return int(text)
    if kind == "table":
        return tuple(float(p) for p in text.split(",")) if text.strip() else ()
    if kind == "optional" and text.lower() == "none":
        return None
    return float(text)


_CONSTANT = ("k", "tau", "tau_n")
_SCHEDULE = ("schedule_speed", "schedule_k", "schedule_tau", "schedule_tau_n")


def loads(text: str, source: str = "calibration") -> ControllerConfig:
    """A calibration from ``key = value`` lines: fields not given keep the shipped values
    (constant ``k``, ``tau``, ``tau_n`` without any ``schedule_*`` line replace the schedule).

    Raises CalibrationError naming the line for an unknown key, a bad value or a calibration
    that ``configure()`` would reject."""
    kinds = _kinds()
    values: dict[str, object] = {}
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#") or line.startswith("c."):
            continue
        key, sep, rest = (p.strip() for p in line.partition("="))
        if not sep:
            raise CalibrationError(f"{source}:{number}: expected 'key = value', got {raw!r}")
        if key not in kinds:
            raise CalibrationError(f"{source}:{number}: unknown key {key!r}")
        try:
            values[key] = _value(kinds[key], rest)
        except ValueError:
            raise CalibrationError(f"{source}:{number}: {key}: not a valid value: {rest!r}") from None
    if any(k in values for k in _CONSTANT) and not any(k in values for k in _SCHEDULE):
        values.update(dict.fromkeys(_SCHEDULE, ()))  # constant gains by hand replace the shipped schedule
    cfg = ControllerConfig(**values)  # type: ignore[arg-type]
    try:
        validate(cfg)
    except ValueError as exc:
        raise CalibrationError(f"{source}: {exc}") from None
    return cfg


def load(path: Path) -> ControllerConfig:
    try:
        text = path.read_text()
    except OSError as exc:
        raise CalibrationError(f"cannot read calibration {path}: {exc.strerror or exc}") from None
    return loads(text, str(path))
