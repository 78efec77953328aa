"""Tables in the docs that are generated from the code, so that a threshold is written once.

``python -m mrsteer_cli.doc_tables --write`` renders them into their files between marker
comments; ``--check`` (and tests/test_doc_tables.py) fails when a file's table differs from what
the code gives today.  The one table so far: docs/controller.md's thresholds of the plausibility
monitor, from ``firmware_py.plausibility.PlausibilityConfig``'s defaults and each field's comment
(``# [unit] meaning`` on the lines directly above the field).
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import sys
from pathlib import Path

from firmware_py import plausibility as pl
from firmware_py.platform.cli import Parser

ROOT = Path(__file__).resolve().parents[1]
CONTROLLER_MD = ROOT / "docs" / "controller.md"
COMMAND = "python -m mrsteer_cli.doc_tables --write"
#: The table's markers in docs/controller.md; what lies between them is the generator's.
BEGIN = "<!-- generated: plausibility-config (" + COMMAND + ") -->"
END = "<!-- end generated -->"

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


def render(text: str) -> str:
    """``text`` (docs/controller.md) with the table between its markers regenerated."""
    start = text.index(BEGIN) + len(BEGIN)
    end = text.index(END, start)
    return text[:start] + "\n" + plausibility_table() + text[end:]


def check(path: Path = CONTROLLER_MD) -> bool:
    """True when the table in ``path`` is what the code gives today."""
    text = path.read_text(encoding="utf-8")
    return render(text) == text


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="python -m mrsteer_cli.doc_tables", description=__doc__.splitlines()[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", action="store_true", help="regenerate the tables in place")
    mode.add_argument("--check", action="store_true", help="exit 1 when a table is not current")
    args = parser.parse_args(argv)
    if args.check:
        if check():
            return 0
        print(f"{CONTROLLER_MD.relative_to(ROOT)}: the plausibility table is stale; run: {COMMAND}",
              file=sys.stderr)
        return 1
    text = CONTROLLER_MD.read_text(encoding="utf-8")
    CONTROLLER_MD.write_text(render(text), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
