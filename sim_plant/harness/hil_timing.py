"""Whether a HIL run's loops held their timing, from the processes' statistics (``--stats-out``
of the controller, Python or C, and of the plant; ``summary.json``'s ``loop``).

The rule: a realtime run held its timing when no cycle of the controller and no step of the
plant started a whole period late (an overrun; the controller skips the periods it lost, its
missed cycles, the plant makes its steps up), and each one's cycle-start lateness p99 was at most
``HELD_P99`` of the period: later than that, a command answers its measurement nearer the next
one than its own.  A lockstep run's time is the plant's steps, not the wall clock: it has no
verdict (``held`` None).
"""

from __future__ import annotations

from typing import Any

HELD_P99 = 0.5  # of the period: the most p99 lateness a run that held its timing has
PROCESSES = ("controller", "plant")
FIGURES = ("overruns", "missed_cycles", "lateness_p99_s", "lateness_max_s")


def timing(loop: dict[str, dict[str, Any]], mode: str, rate_hz: float) -> dict[str, Any]:
    """``summary.json``'s ``timing``: the verdict (``held``), the rule, and each process's figures
    (a process that reports none of them, e.g. no controller, is left out)."""
    period = 1.0 / rate_hz
    figures = {name: {k: loop.get(name, {}).get(k) for k in FIGURES} for name in PROCESSES}
    figures = {name: {k: v for k, v in f.items() if v is not None} for name, f in figures.items()}
    figures = {name: f for name, f in figures.items() if f}
    held = all(_held(f, period) for f in figures.values()) if mode == "realtime" else None
    return {"held": held, "period_s": period,
            "rule": f"no overrun or missed cycle, lateness p99 at most {HELD_P99:g} period (realtime runs)",
            **figures}


def _held(figures: dict[str, Any], period: float) -> bool:
    return (figures.get("overruns", 0) == 0 and figures.get("missed_cycles", 0) == 0
            and figures.get("lateness_p99_s", 0.0) <= HELD_P99 * period)


def process_line(figures: dict[str, Any]) -> str:
    """One process's figures in words: ``overruns 38, missed cycles 44, lateness p99 5.16 ms, max 6.1 ms``."""
    parts = [f"overruns {figures.get('overruns', 0)}"]
    if "missed_cycles" in figures:
        parts.append(f"missed cycles {figures['missed_cycles']}")
    elif figures.get("overruns", 0):
        parts.append("late steps made up, none skipped")
    if "lateness_p99_s" in figures:
        parts.append(f"lateness p99 {1e3 * figures['lateness_p99_s']:.3g} ms")
    if "lateness_max_s" in figures:
        parts.append(f"max {1e3 * figures['lateness_max_s']:.3g} ms")
    return ", ".join(parts)


def verdict_line(t: dict[str, Any]) -> str:
    """The verdict in one plain line."""
    period = f"{1e3 * t['period_s']:g} ms"
    if t["held"] is None:
        return "lockstep: the plant's steps set the time, not the wall clock"
    if t["held"]:
        return f"held: no overrun or missed cycle, lateness p99 within half the {period} period"
    late = [name for name in PROCESSES if name in t and not _held(t[name], t["period_s"])]
    return (f"did NOT hold: the {' and the '.join(late)} ran late of the {period} period (a loaded "
            "machine?); this run's figures are not those of loops that kept their period")


def lines(t: dict[str, Any], indent: str = "  ", width: int = 26) -> list[str]:
    """What ``hil run`` prints of it: a line per process (realtime runs), then the verdict."""
    shown = PROCESSES if t["held"] is not None else ()
    out = [f"{indent}{'timing ' + name:<{width}}{process_line(t[name])}" for name in shown if name in t]
    return out + [f"{indent}{'timing':<{width}}{verdict_line(t)}"]
