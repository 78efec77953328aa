"""The firmware's functions stay short and simple: no function in ``firmware_py/`` or
``ports/c/`` longer than 60 lines or of a cyclomatic complexity over 15, as ``lizard`` measures
them (the porting rules; issue 52).  Generated code (the DBC codec and the node contract glue,
written into ``ports/c/build/``, and ``mrs_defaults.h`` from the calibration) is not ours to
shape and is not measured.

The functions over the limits when the limits came in are listed with their figures: the list
may only shrink.  The test fails on a function over the limits that is not listed, on a listed
one whose length or complexity grew, and on a listed one that now fits (remove it)."""

from __future__ import annotations

from pathlib import Path

import pytest

lizard = pytest.importorskip("lizard", reason="lizard is not installed (pip install -e '.[test]')")

ROOT = Path(__file__).resolve().parents[1]
ROOTS = ("firmware_py", "ports/c")
GENERATED = ("ports/c/build", "ports/c/mrs_defaults.h")
MAX_LENGTH = 60  # lines, lizard's "length"
MAX_CCN = 15

# (file, function): (length, cyclomatic complexity) when the limits came in.  Only shrinks.
KNOWN_OFFENDERS: dict[tuple[str, str], tuple[int, int]] = {
    ("ports/c/fuzz_oracle.c", "fv_sound"): (29, 16),
    ("ports/c/fuzz_oracle.c", "oracle_judge"): (55, 27),
    ("ports/c/fuzz_rx.c", "mutate"): (42, 18),
    ("ports/c/fuzz_rx.c", "sensor_event"): (81, 69),
    ("ports/c/fuzz_rx.c", "main"): (50, 20),
    ("ports/c/gen_codec_check.py", "harness"): (87, 3),
    ("ports/c/gen_node_contract.py", "header"): (66, 9),
    ("ports/c/mrs_bus_socketcan.c", "sc_recv"): (51, 17),
    ("ports/c/mrs_config.c", "set_key"): (53, 16),
    ("ports/c/mrs_config.c", "mrs_config_load"): (61, 22),
    ("ports/c/mrs_node.c", "run_on_clock"): (53, 17),
    ("ports/c/mrs_node_core.c", "mrs_node_init"): (98, 13),
    ("ports/c/mrs_node_opts.c", "one"): (84, 29),
    ("ports/c/mrs_node_opts.c", "controller_config"): (39, 18),
    ("ports/c/mrs_node_opts.c", "check"): (39, 24),
    ("ports/c/mrs_replay.c", "main"): (88, 22),
    ("ports/c/mrs_secoc.c", "mrs_secoc_load_key"): (54, 17),
    ("ports/c/mrs_vectors.c", "mrs_vectors_main"): (80, 14),
    ("ports/c/pil/budget.py", "main"): (38, 16),
    ("ports/c/secoc_check.c", "main"): (72, 18),
}


def _sources() -> list[Path]:
    out = []
    for root in ROOTS:
        for path in sorted((ROOT / root).rglob("*")):
            rel = path.relative_to(ROOT).as_posix()
            if path.suffix in (".py", ".c", ".h") and not rel.startswith(GENERATED):
                out.append(path)
    return out


def measure() -> dict[tuple[str, str], tuple[int, int]]:
    """Every function of the sources over a limit: (file, name) -> (length, CCN); the largest
    figures when a file has two functions of one name."""
    over: dict[tuple[str, str], tuple[int, int]] = {}
    for path in _sources():
        rel = path.relative_to(ROOT).as_posix()
        for fn in lizard.analyze_file(str(path)).function_list:
            if fn.length > MAX_LENGTH or fn.cyclomatic_complexity > MAX_CCN:
                old = over.get((rel, fn.name), (0, 0))
                over[(rel, fn.name)] = (max(old[0], fn.length), max(old[1], fn.cyclomatic_complexity))
    return over


def offences(over: dict[tuple[str, str], tuple[int, int]],
             known: dict[tuple[str, str], tuple[int, int]]) -> list[str]:
    """What the figures break: a new offender, a known one grown, a known one that now fits."""
    out = []
    for key, (length, ccn) in sorted(over.items()):
        if key not in known:
            out.append(f"{key[0]}: {key[1]} has {length} lines, CCN {ccn} (limits {MAX_LENGTH}, {MAX_CCN})")
        elif length > known[key][0] or ccn > known[key][1]:
            out.append(f"{key[0]}: {key[1]} grew to {length} lines, CCN {ccn} (listed {known[key]})")
    for key in sorted(set(known) - set(over)):
        out.append(f"{key[0]}: {key[1]} fits the limits now: remove it from KNOWN_OFFENDERS")
    return out


def test_no_function_over_the_limits_but_the_listed_ones() -> None:
    problems = offences(measure(), KNOWN_OFFENDERS)
    assert not problems, "\n".join(problems)


def test_the_measure_finds_a_long_complex_function(tmp_path: Path) -> None:
    # the oracle: a function written to be 71 lines long (def, 40 + 29 lines, return) with 20 decisions
    body = "".join(f"    if x == {k}:\n        x += 1\n" for k in range(20))
    body += "".join("    x += 1\n" for _ in range(29))
    path = tmp_path / "long.py"
    path.write_text("def long_one(x):\n" + body + "    return x\n")
    fn = lizard.analyze_file(str(path)).function_list[0]
    assert (fn.length, fn.cyclomatic_complexity) == (71, 21)
    assert offences({("f.py", "long_one"): (70, 21)}, {}) and offences({("f.py", "g"): (70, 21)},
                                                                       {("f.py", "g"): (61, 21)})
    assert offences({}, {("f.py", "g"): (61, 21)}) and not offences({("f.py", "g"): (61, 21)},
                                                                    {("f.py", "g"): (61, 21)})
