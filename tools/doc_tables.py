"""Tables in the docs that are generated from the code, so that a threshold is written once.

``python -m mrsteer_cli.doc_tables --write`` renders them into their files between marker
comments; ``--check`` (and tests/test_doc_tables.py) fails when a file's table differs from what
the code, or the committed output of a real run, gives today.  The tables (``TABLES``):

* docs/controller.md ``plausibility-config``: the monitor's thresholds, from
  ``PlausibilityConfig``'s defaults and each field's comment (``# [unit] meaning`` above it);
* docs/design.md ``shipped-schedule``: the shipped calibration's schedule (``calibration.SHIPPED_*``);
* docs/design.md ``tradeoff``: ``mrsteer design compare``'s table, from the run that wrote
  ``docs/figures/tradeoff.json``;
* docs/design.md ``busload``: the DBC's load per control rate and the highest rate per budget
  (``mrsteer_dbc.busload``);
* docs/campaigns.md ``campaign-results``: each shipped campaign's pass rates, from the summary
  ``mrsteer campaign report DIR --json`` wrote of a run of it (``campaigns/results/NAME.json``).
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import sys
import json
from collections.abc import Callable
from pathlib import Path

import mrsteer_dbc
from firmware_py import calibration as cal
from firmware_py import plausibility as pl
from mrsteer_dbc.busload import BITRATE, bus_load, max_rate_hz
from firmware_py.platform.cli import Parser

ROOT = Path(__file__).resolve().parents[1]
CONTROLLER_MD = ROOT / "docs" / "controller.md"
DESIGN_MD = ROOT / "docs" / "design.md"
CAMPAIGNS_MD = ROOT / "docs" / "campaigns.md"
TRADEOFF_JSON = ROOT / "docs" / "figures" / "tradeoff.json"
CAMPAIGN_RESULTS = ROOT / "campaigns" / "results"
COMMAND = "python -m mrsteer_cli.doc_tables --write"
END = "<!-- end generated -->"


def begin(name: str) -> str:
    """A table's opening marker; what lies between it and the next END is the generator's."""
    return f"<!-- generated: {name} ({COMMAND}) -->"


#: docs/controller.md's table of the plausibility monitor's thresholds.
BEGIN = begin("plausibility-config")

_FIELD = re.compile(r"^\s+(\w+)\s*:\s*[\w.\[\]| ]+=")
_COMMENT = re.compile(r"^\s+#\s?(.*)$")
_UNIT = re.compile(r"^\[([^\]]+)\]\s*(.*)$")


def field_comments(cls: type) -> dict[str, tuple[str, str]]:
    """{field: (unit, meaning)} from the comment lines directly above each field of ``cls``."""
    out: dict[str, tuple[str, str]] = {}
    above: list[str] = []
    for line in inspect.getsource(cls).splitlines():
        comment = _COMMENT.match(line)
        if comment:
            above.append(comment.group(1).strip())
            continue
        field = _FIELD.match(line)
        if field and above:
            unit = _UNIT.match(" ".join(above))
            if unit:
                out[field.group(1)] = (unit.group(1), unit.group(2))
        above = []
    return out


def _value(value: object, unit: str) -> str:
    text = str(value) if isinstance(value, int) else f"{value:g}"
    return text if unit == "1" else f"{text} {unit}"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def plausibility_table() -> str:
    """The Markdown table of ``PlausibilityConfig``'s fields: name, default with unit, meaning."""
    comments = field_comments(pl.PlausibilityConfig)
    defaults = pl.PlausibilityConfig()
    rows = ["| field | default | meaning |", "|---|---|---|"]
    for f in dataclasses.fields(pl.PlausibilityConfig):
        if f.name not in comments:
            raise ValueError(f"PlausibilityConfig.{f.name} has no '# [unit] meaning' comment above it")
        unit, meaning = comments[f.name]
        rows.append(f"| `{f.name}` | {_cell(_value(getattr(defaults, f.name), unit))} | {_cell(meaning)} |")
    return "\n".join(rows) + "\n"


def schedule_table() -> str:
    """The shipped calibration's gains at each speed breakpoint (eqs. 18 and 22)."""
    k, tau, tau_n = cal.SHIPPED_K, cal.SHIPPED_TAU, cal.SHIPPED_TAU_N
    rows = [("K", [f"{x:g}" for x in k]),
            ("τ_Q = τ/(1 + K) (ms)", [f"{1e3 * t / (1 + g):.2f}" for g, t in zip(k, tau)]),
            ("τ of eq. (22) (ms)", [f"{1e3 * t:.4g}" for t in tau]),
            ("τ_n of eq. (18) (ms)", [f"{1e3 * t:.4g}" for t in tau_n]),
            ("steady compensation K/(1 + K)", [f"{100 * g / (1 + g):.1f} %" for g in k])]
    out = ["| v (m/s) | " + " | ".join(f"{v:g}" for v in cal.SHIPPED_SPEED) + " |",
           "|---|" + "---|" * len(cal.SHIPPED_SPEED)]
    out += [f"| {name} | " + " | ".join(cells) + " |" for name, cells in rows]
    return "\n".join(out) + (f"\n\nNominal actuator {1e3 * cal.SHIPPED_MODEL_ACTUATOR_TAU:g} ms, nominal filter "
                             f"{cal.SHIPPED_MODEL_FILTER_HZ:g} Hz.\n")


def tradeoff_table(path: Path = TRADEOFF_JSON) -> str:
    """``mrsteer design compare``'s table, from the JSON its run wrote."""
    from sim_plant.offline import compare as K

    data = json.loads(path.read_text(encoding="utf-8"))
    result = {name: {loop: K.LoopFigures(**figures) for loop, figures in loops.items()}
              for name, loops in data["rows"].items()}
    return f"Assumes: {data['assumes']}.\n\n" + K.markdown(result) + "\n"


#: The control rates, bitrates and load budgets the bus-load tables show.
_RATES_HZ = (1000.0, 500.0, 200.0, 100.0)
_BITRATES = (250_000, 500_000, 1_000_000)
_BUDGETS = (40.0, 60.0, 100.0)


def busload_table() -> str:
    """The DBC's load at each control rate at 500 kbit/s, and the highest rate per budget."""
    contract = mrsteer_dbc.load()
    out = [f"| control rate | nominal load at {BITRATE / 1000:g} kbit/s | worst case |", "|---|---|---|"]
    for rate in _RATES_HZ:
        load = bus_load(contract, BITRATE, rate)
        out.append(f"| {rate:g} Hz | {load.load_percent_nominal:.1f} % | {load.load_percent_worst:.1f} % |")
    out += ["", "Highest control rate whose worst-case load stays within a budget:", "",
            "| bitrate | " + " | ".join(f"{b:g} %" for b in _BUDGETS) + " |", "|---|" + "---|" * len(_BUDGETS)]
    for bitrate in _BITRATES:
        cells = " | ".join(f"{max_rate_hz(contract, bitrate, b):.0f} Hz" for b in _BUDGETS)
        out.append(f"| {bitrate / 1000:g} kbit/s | {cells} |")
    return "\n".join(out) + "\n"


def _share(x: float | None) -> str:
    return "—" if x is None else f"{100 * x:.1f} %"


def campaign_results_table(folder: Path | None = None) -> str:
    """One row per campaign summary in ``folder`` and calibration: runs, passed, spun, and each
    criterion's failures (how many failed it alone in brackets) with its largest figure."""
    out = ["| campaign | calibration | runs | passed | spun | failed: criterion (alone), largest figure |",
           "|---|---|---|---|---|---|"]
    for path in sorted((folder or CAMPAIGN_RESULTS).glob("*.json")):
        try:
            summary = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not a campaign summary ({e}); write it with `mrsteer campaign report DIR --json`") from e
        for name, c in summary["calibrations"].items():
            failed = []
            for k, f in c["failed"].items():
                largest = c["figures"].get(k, {}).get("max")
                fig = "" if largest is None else f", {largest:.4g}"
                failed.append(f"`{k}` {f['runs']} ({f['alone']}){fig}")
            out.append(f"| `{path.stem}` | {name} | {c['runs']} | {c['passed']} ({_share(c['pass_rate'])}) | "
                       f"{c['spun']} | {'; '.join(failed) or '—'} |")
    return "\n".join(out) + "\n"


#: name -> (the file it is in, its generator)
TABLES: dict[str, tuple[Path, Callable[[], str]]] = {
    "plausibility-config": (CONTROLLER_MD, plausibility_table),
    "shipped-schedule": (DESIGN_MD, schedule_table),
    "tradeoff": (DESIGN_MD, tradeoff_table),
    "busload": (DESIGN_MD, busload_table),
    "campaign-results": (CAMPAIGNS_MD, campaign_results_table),
}


def render(text: str, path: Path = CONTROLLER_MD) -> str:
    """``text`` (the file ``path``) with every table of that file regenerated between its markers."""
    for name, (where, generate) in TABLES.items():
        if where != path:
            continue
        mark = begin(name)
        if mark not in text:
            raise ValueError(f"{path.name}: no marker {mark}")
        start = text.index(mark) + len(mark)
        end = text.index(END, start)
        text = text[:start] + "\n" + generate() + text[end:]
    return text


def stale(paths: tuple[Path, ...] | None = None) -> list[Path]:
    """The files whose tables are not what the code and the committed runs give today."""
    files = paths if paths is not None else tuple(dict.fromkeys(p for p, _ in TABLES.values()))
    return [p for p in files if render(p.read_text(encoding="utf-8"), p) != p.read_text(encoding="utf-8")]


def check(path: Path | None = None) -> bool:
    """True when the tables in ``path`` (default: every file with one) are current."""
    return not stale(None if path is None else (path,))


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="python -m mrsteer_cli.doc_tables", description=__doc__.splitlines()[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", action="store_true", help="regenerate the tables in place")
    mode.add_argument("--check", action="store_true", help="exit 1 when a table is not current")
    args = parser.parse_args(argv)
    try:
        return _run(args.check)
    except (ValueError, OSError, KeyError) as e:
        print(f"doc_tables: {e}", file=sys.stderr)
        return 2


def _run(check_only: bool) -> int:
    if check_only:
        old = stale()
        if not old:
            return 0
        print(f"{', '.join(str(p.relative_to(ROOT)) for p in old)}: a generated table is stale; run: {COMMAND}",
              file=sys.stderr)
        return 1
    for path in dict.fromkeys(p for p, _ in TABLES.values()):
        text = path.read_text(encoding="utf-8")
        path.write_text(render(text, path), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
