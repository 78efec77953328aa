"""Figures as people and JSON read them: rounded to their resolution.  One helper for every output
(summaries printed or in JSON, the CSVs), so a figure reads the same everywhere; a per-step
table's states keep more digits (``tidy_datum``), being data to analyse.

A figure's resolution follows from its name's unit suffix: an angle (``_rad``) to the bus's
finest angle, the command's 1e-6 rad; degrees (``_deg``) to 1e-5 deg (about that angle); a time
(``_s``) to the log's microsecond; the other SI quantities (``_rad_s``, ``_m_s``, ``_m_s2``) to
1e-6 of their unit.  A signal decoded from the bus is rounded to its DBC scale instead.  A figure
with no unit (a gain, a ratio) keeps ``DIGITS`` significant digits.  A value below its
resolution is 0; numbers stay numbers (JSON remains machine-readable), only their float noise
(``0.020300000000000002``, ``-1.16e-164``) goes.
"""

from __future__ import annotations

import functools
import math
from decimal import Decimal
from typing import Any

import mrsteer_dbc
from mrsteer_dbc.names import MSG_CMD, SIG_CMD_ANGLE

DIGITS = 6  # significant digits of a figure without a unit
DATA_DIGITS = 9  # significant digits of a state in a per-step table (steps.csv): data to analyse
ROUND_OFF = 1e-12  # of a state's unit: below it, a value in such a table is round-off, written 0
SI = 1e-6  # of its unit: a figure of the plant's states (yaw rate, speed, acceleration)
LOG_TIME = 1e-6  # s: the candump log's timestamps


@functools.cache
def _resolutions() -> tuple[tuple[str, float], ...]:
    """By name suffix, longest first (``_rad_s`` before ``_s``)."""
    angle = mrsteer_dbc.load().signal_scale(MSG_CMD, SIG_CMD_ANGLE)
    deg = 10.0 ** math.floor(math.log10(math.degrees(angle)))
    return (("_m_s2", SI), ("_rad_s", SI), ("_m_s", SI), ("_rad", angle), ("_deg", deg), ("_s", LOG_TIME))


def resolution_of(name: str) -> float | None:
    """The resolution of a figure called ``name`` (None: no unit, significant digits)."""
    return next((res for suffix, res in _resolutions() if name.endswith(suffix)), None)


def tidy(x: float, resolution: float | None = None) -> float:
    """``x`` rounded to ``resolution`` (a multiple of it, written with no more decimals than it
    has), or to ``DIGITS`` significant digits without one; non-finite values as they are."""
    if not math.isfinite(x):
        return x
    if resolution is None:
        return tidy_digits(x, DIGITS)
    decimals = max(0, -Decimal(repr(resolution)).normalize().as_tuple().exponent)  # type: ignore[operator]
    return round(round(x / resolution) * resolution, decimals) + 0.0  # + 0.0: no -0.0


def tidy_datum(x: float) -> float:
    """A plant state for a per-step table: ``DATA_DIGITS`` significant digits, and 0 below
    ``ROUND_OFF`` (``-1.16e-164`` rad of an actuator at rest)."""
    return 0.0 if abs(x) < ROUND_OFF else tidy_digits(x, DATA_DIGITS)


def tidy_digits(x: float, digits: int) -> float:
    return float(f"{x:.{digits}g}") + 0.0 if math.isfinite(x) else x


def tidy_figures(value: Any, name: str = "") -> Any:
    """``value`` with every float in it tidied by the name it is filed under (dicts by key;
    lists and tuples by their own name); other values as they are."""
    if isinstance(value, bool) or not isinstance(value, (float, dict, list, tuple)):
        return value
    if isinstance(value, float):
        return tidy(value, resolution_of(name))
    if isinstance(value, dict):
        return {k: tidy_figures(v, str(k)) for k, v in value.items()}
    return [tidy_figures(v, name) for v in value]


def text(value: Any, name: str = "") -> str:
    """One figure as text: a float tidied (``1e-05``, ``0.0203``, ``25``), anything else as str."""
    v = tidy_figures(value, name)
    return written(v) if isinstance(v, float) else str(v)


def written(x: float) -> str:
    """A float already tidied, as text: a whole number without its ``.0``."""
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def lines(figures: dict[str, Any], indent: str = "  ", width: int = 26) -> list[str]:
    """``key value`` lines, a nested mapping as its key on a line of its own and its own lines
    indented below it: what a summary prints instead of a dict's repr."""
    out = []
    for key, value in figures.items():
        if isinstance(value, dict):
            out.append(f"{indent}{key}")
            out.extend(lines(value, indent + "  ", max(1, width - 2)))
        elif isinstance(value, (list, tuple)):
            out.append(f"{indent}{key:<{width}}{', '.join(text(v, key) for v in value) or '-'}")
        else:
            out.append(f"{indent}{key:<{width}}{text(value, key)}")
    return out
