"""One owner of the control cycle: the plausibility monitor, the law and the authority limiter are
composed into one period in one place per language (``firmware_py/cycle.py``, its C port
``ports/c/mrs_cycle.c``; docs/porting.md, "Scheduling contract").  Everything else runs a cycle
by calling those, so a change of the order or of a flag passed between the pieces is made once.

The guard: no other module calls a piece's step function itself.  Calls count, not mentions (a
docstring or a comment naming ``monitor_step(...)`` is no call).  The campaign engine steps its
controllers through the C cycle (``ports/c/mrs_cycle_batch.c``: ``mrs_cycle_step`` per row)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PORT = ROOT / "ports" / "c"

# ---------------------------------------------------------------------------------------- C

C_PIECES = ("mrs_monitor_step", "mrs_authority_step")
C_ALLOWED = {
    "mrs_cycle.c": "the cycle",
    "mrs_monitor.c": "the pieces' own file",
    "mrs_monitor.h": "the pieces' own header (their declarations)",
    "monitor_vectors.c": "the monitor's and the limiter's unit test: it feeds the limiter an applied "
                         "command of its own, which a whole cycle cannot",
}
# Not a control cycle: the batch loop runs the simulated actuators' own authority limiters (as
# PY_NOT_A_CYCLE's actuator.py) for the campaign engine; its controllers are mrs_cycle_step's.
C_NOT_A_CYCLE = {
    "mrs_cycle_batch.c": {"mrs_authority_step"},
}

# ----------------------------------------------------------------------------------- Python

PY_ROOTS = ("firmware_py", "sim_plant", "tools", "bench")
# The monitor's units (one per check family, firmware_py/plausibility.py): each is a part of
# monitor_step, which is the only one to call them in order.  (Their C twins are static in
# mrs_monitor.c: nothing else can call them.)
PY_MONITOR_UNITS = ("speed_step_check", "speed_pair_check", "input_flags", "redundant_frame_lost", "monitor_pause",
                    "monitor_start", "model_check", "yaw_pair_check", "yaw_pair_suspicion", "steer_jump_check",
                    "redundant_checks", "kinematic_sample", "kinematic_residual", "kinematic_check", "steer_pair_check",
                    "turn_block_start", "turn_check", "frozen_checks", "frozen_yaw_check", "frozen_lat_check",
                    "frozen_steer_check", "frozen_steer2_check", "monitor_finish")
# The limiter's units (firmware_py/authority.py), likewise parts of authority_step.
PY_AUTHORITY_UNITS = ("fade_cause", "magnitude_bound", "rate_bound", "intervention_window")
# PlausibilityMonitor is monitor_step in an object: constructing one is running the monitor.
PY_PIECES = ("monitor_step", "authority_step", "PlausibilityMonitor", *PY_MONITOR_UNITS, *PY_AUTHORITY_UNITS)
PY_OWNERS = {
    "firmware_py/cycle.py": "the cycle",
    "firmware_py/plausibility.py": "the monitor's own module",
    "firmware_py/authority.py": "the limiter's own module",
}
# Not a control cycle: the simulated actuator ECU runs an authority limiter of its own on the
# commands it receives (with the controller's last CtrlStatus_Plausibility bits), no monitor and
# no law.  Only authority_step is allowed there.
PY_NOT_A_CYCLE = {
    "sim_plant/car/actuator.py": {"authority_step"},
}
# Not a control cycle: the monitor's behaviour-identity check records the monitor's whole state
# and the limiter's answer on its own inputs, as monitor_vectors.c does in C.
PY_NOT_A_CYCLE["tools/monitor_identity.py"] = {"monitor_step", "authority_step"}
def _strip_c_comments(text: str) -> str:
    return re.sub(r"//[^\n]*", "", re.sub(r"/\*.*?\*/", " ", text, flags=re.S))


def c_calls(text: str) -> set[str]:
    """The pieces' step functions ``text`` (C source) calls or declares, comments aside."""
    code = _strip_c_comments(text)
    return {fn for fn in C_PIECES if re.search(rf"\b{fn}\s*\(", code)}


def py_calls(text: str) -> set[str]:
    """The pieces ``text`` (a Python module) calls, by name or as an attribute (``pl.monitor_step(...)``)."""
    found = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
            if name in PY_PIECES:
                found.add(name)
    return found


def _c_offenders() -> dict[str, set[str]]:
    out = {}
    for path in sorted([*PORT.glob("*.c"), *PORT.glob("*.h")]):  # not build/: generated, none of it the cycle's
        calls = c_calls(path.read_text(errors="replace")) - C_NOT_A_CYCLE.get(path.name, set())
        if calls and path.name not in C_ALLOWED:
            out[path.name] = calls
    return out


def _py_calls_by_module() -> dict[str, set[str]]:
    out = {}
    for root in PY_ROOTS:
        for path in sorted((ROOT / root).rglob("*.py")):
            calls = py_calls(path.read_text())
            if calls:
                out[path.relative_to(ROOT).as_posix()] = calls
    return out


def test_only_mrs_cycle_calls_the_monitor_and_the_limiter_in_c() -> None:
    assert (PORT / "mrs_cycle.c").is_file()
    assert c_calls((PORT / "mrs_cycle.c").read_text()) == set(C_PIECES)  # the guard looks at the right thing
    assert _c_offenders() == {}, "compose a cycle with mrs_cycle_step (ports/c/mrs_cycle.h)"


def test_only_firmware_py_cycle_calls_the_monitor_and_the_limiter_in_python() -> None:
    calls = _py_calls_by_module()
    assert calls.get("firmware_py/cycle.py") == {"monitor_step", "authority_step"}
    offenders = {}
    for module, pieces in calls.items():
        allowed = set(PY_PIECES) if module in PY_OWNERS else PY_NOT_A_CYCLE.get(module, set())
        if pieces - allowed:
            offenders[module] = pieces - allowed
    assert offenders == {}, "run a control period with firmware_py.cycle (step, or Cycle)"


def test_the_monitor_units_are_the_monitors_functions() -> None:
    import firmware_py.authority as au
    import firmware_py.plausibility as pl
    for name in PY_MONITOR_UNITS:
        assert callable(getattr(pl, name, None)), name
    for name in PY_AUTHORITY_UNITS:
        assert callable(getattr(au, name, None)), name
    assert "speed_pair_check" in py_calls((ROOT / "firmware_py" / "plausibility.py").read_text())


def test_the_allowlists_name_files_that_exist() -> None:
    for name in C_ALLOWED:
        assert (PORT / name).is_file(), name
    for module in (*PY_OWNERS, *PY_NOT_A_CYCLE):
        assert (ROOT / module).is_file(), module


@pytest.mark.parametrize(("text", "expected"), [
    ("u = au.authority_step(c, s, u, bits, 0, 0)\n", {"authority_step"}),
    ("from firmware_py.plausibility import monitor_step\nb = monitor_step(c, s, 0, 0, 0, 0, 0, 0, 0, 0)\n",
     {"monitor_step"}),
    ("m = pl.PlausibilityMonitor(cfg)\n", {"PlausibilityMonitor"}),
    ('"""``monitor_step(c, s, ...)`` for N rows at once."""\n# authority_step(...) in a comment\n', set()),
    ("f = au.authority_step\n", set()),  # a reference, not a call: found where it is called
])
def test_the_python_guard_sees_calls_not_mentions(text: str, expected: set[str]) -> None:
    assert py_calls(text) == expected


@pytest.mark.parametrize(("text", "expected"), [
    ("x = mrs_monitor_step(&c, &s, a, b, r, l, v, u, r2, v2);\n", {"mrs_monitor_step"}),
    ("u = mrs_authority_step (&c, &s, u, b, 0u, 0u);\n", {"mrs_authority_step"}),
    ("/* mrs_monitor_step() and\n * mrs_authority_step() */\n// mrs_monitor_step(\n", set()),
    ("x = my_mrs_monitor_step(a);\n", set()),
])
def test_the_c_guard_sees_calls_not_comments(text: str, expected: set[str]) -> None:
    assert c_calls(text) == expected
