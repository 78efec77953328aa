"""The processor-in-the-loop target's verdict and budget (``make -C ports/c pil``).

    python pil/budget.py BUILD_PIL CORE... [--write DOC | --check DOC]

Reads what the target left in BUILD_PIL (``CORE/results.txt`` from pil/run.sh, the objects with
their ``.su``/``.ci`` files, ``pil.elf``) and

* checks every vector: the target's line for each file must be the host runner's own line
  (``./run_vectors_f64`` for the float64 core, ``./run_vectors_f32`` for the float32 one), and
  the float64 core's differences to the Python firmware all exactly 0;
* prints the budget table: flash and RAM of the controller's objects (``arm-none-eabi-size``),
  the worst stack of one step and of one cycle (``-fcallgraph-info=su`` over the call graph, and
  the target's painted stack), the instructions per step and per cycle (the emulator's count);
* ``--write DOC`` puts the table between its markers in DOC, ``--check DOC`` fails if DOC's is not it.

Exit 0, or 1 with one line per failing vector / a stale table, or 2 with one line on bad usage.
"""

from __future__ import annotations

import re
import statistics
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
PORT = HERE.parent
sys.path.insert(0, str(PORT.parents[1]))  # the repository's firmware_py, with or without the venv

from firmware_py.platform.cli import Parser  # noqa: E402 - bad usage: one line, exit 2, as every command's
VECTORS = PORT.parents[1] / "tests" / "vectors"
COMMAND = "make -C ports/c pil-table"
BEGIN = "<!-- generated: pil-budget (" + COMMAND + ") -->"
END = "<!-- end generated -->"
PERIOD_S = 0.002  # the shipped 500 Hz control period


@dataclass(frozen=True)
class Core:
    name: str
    title: str
    host_runner: str
    clock_hz: float  # the stated clock: a typical part of that core

    @property
    def exact(self) -> bool:
        """float64: bit for bit with the Python firmware."""
        return self.host_runner.endswith("f64")


CORES = {
    "m4f": Core("m4f", "Cortex-M4F, float32 (`mps2-an386`)", "run_vectors_f32", 168e6),
    "m7": Core("m7", "Cortex-M7, float64 (`mps2-an500`)", "run_vectors_f64", 300e6),
}
CONTROLLER_OBJECTS = ("mrs_controller.o", "mrs_cycle.o", "mrs_monitor.o", "mrs_e2e.o")
ERRORS = ("coeff_rel_err", "u_err", "z_err", "hist_err", "model_err")
MISMATCHES = ("status_mismatch", "flags_mismatch", "idx_mismatch", "init_mismatch")


@dataclass
class Results:
    lines: dict[str, str]  # vector file -> the target's runner line
    steps: int
    counts: dict[str, list[int]]  # "law" / "cycle" -> instructions of each row
    stack: dict[str, int]  # "law_stack" / "cycle_stack" -> painted bytes; the structs' sizes
    zero: dict[str, int]  # the markers back to back: must count 0


def read_results(path: Path) -> Results:
    lines: dict[str, str] = {}
    counts: dict[str, list[int]] = {"law": [], "cycle": []}
    stack: dict[str, int] = {}
    zero: dict[str, int] = {}
    name = ""
    for line in path.read_text(encoding="utf-8").splitlines():
        word = line.split(" ", 1)[0]
        if word == "file":
            name = line.split(" ", 1)[1]
            zero_seen: set[str] = set()
        elif word.startswith("steps="):
            lines[name] = line
        elif word == "pil:":
            for key, value in re.findall(r"(\w+)=(\d+)", line):
                stack[key] = max(stack.get(key, 0), int(value))
        elif word in counts:
            n = int(line.split()[1])
            if word not in zero_seen:  # each run's first pair is the empty one
                zero_seen.add(word)
                zero[word] = max(zero.get(word, 0), n)
            else:
                counts[word].append(n)
    steps = sum(int(re.search(r"steps=(\d+)", v).group(1)) for v in lines.values())
    return Results(lines, steps, counts, stack, zero)


def verdicts(core: Core, res: Results, vectors: Path) -> list[str]:
    """One line per failure: a vector whose target line is not the host's, or not exact in float64;
    counts missing or not zeroed."""
    failures = []
    for f in sorted(vectors.glob("*__*.csv")):
        got = res.lines.get(f.name)
        cfg = vectors / (f.name.split("__")[0] + ".cfg")
        host = subprocess.run([str(PORT / core.host_runner), str(cfg), str(f)], capture_output=True, text=True,
                              check=True).stdout.strip()
        if got != host:
            failures.append(f"pil {core.name}: {f.name}: target `{got}` differs from the host's `{host}`")
            continue
        figures = dict(re.findall(r"(\w+)=(\S+)", got))
        inexact = core.exact and any(float(figures[e]) != 0 for e in ERRORS)
        if inexact or any(float(figures[m]) != 0 for m in MISMATCHES):
            failures.append(f"pil {core.name}: {f.name}: not exact: {got}")
    if any(n != 0 for n in res.zero.values()) or len(res.zero) != 2:
        failures.append(f"pil {core.name}: the markers back to back count {res.zero}, not 0")
    for kind, counted in res.counts.items():
        if len(counted) != res.steps:
            failures.append(f"pil {core.name}: {len(counted)} counted {kind} steps for {res.steps} rows")
    return failures


def stack_verdicts(core: Core, build: Path, res: Results) -> list[str]:
    """The painted stack against the call graph's worst: deeper than the graph can only be what
    the graph does not know (libgcc's helpers); none painted means the painting is broken."""
    failures = []
    for root, key in (("mrs_step", "law_stack"), ("cycle", "cycle_stack")):
        static, unknown = static_stack(build, root)
        painted = res.stack.get(key, 0)
        if painted == 0 or (not unknown and painted > static):
            failures.append(f"pil {core.name}: {root}'s painted stack {painted} B against {static} B in the call graph")
    return failures


def _tool(*cmd: str) -> str:
    return subprocess.run(list(cmd), capture_output=True, text=True, check=True).stdout


def sizes(build: Path) -> tuple[int, int, int]:
    """text, data, bss of the controller's objects (arm-none-eabi-size)."""
    out = _tool("arm-none-eabi-size", *(str(build / o) for o in CONTROLLER_OBJECTS))
    total = [0, 0, 0]
    for row in out.splitlines()[1:]:
        for i, v in enumerate(row.split()[:3]):
            total[i] += int(v)
    return total[0], total[1], total[2]


def library_calls(build: Path) -> list[str]:
    """What the controller's objects take from libgcc/libm on this core (their undefined symbols)."""
    own = set(_tool("arm-none-eabi-nm", "--defined-only", *(str(build / o) for o in CONTROLLER_OBJECTS)).split())
    undefined = set(_tool("arm-none-eabi-nm", "-u", *(str(build / o) for o in CONTROLLER_OBJECTS)).split())
    return sorted(s for s in undefined - own if s != "U" and not s.endswith(".o:"))


_NODE = re.compile(r'node: \{ title: "([^"]+)" label: "[^"]*?\\n[^"]*?\\n(\d+) bytes \(static\)')
_EDGE = re.compile(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"')


def static_stack(build: Path, root: str) -> tuple[int, list[str]]:
    """Worst stack from root over the call graph of every .ci file (-fcallgraph-info=su), and the
    callees with no figure (libgcc's helpers: not compiled here)."""
    frame: dict[str, int] = {}
    calls: dict[str, set[str]] = {}
    for ci in build.rglob("*.ci"):
        text = ci.read_text(encoding="utf-8")
        frame.update((n, int(b)) for n, b in _NODE.findall(text))
        for src, dst in _EDGE.findall(text):
            calls.setdefault(src, set()).add(dst)
    unknown: set[str] = set()
    root = next((n for n in frame if n == root or n.endswith(":" + root)), root)  # a static's is FILE:NAME

    def worst(fn: str) -> int:
        if fn not in frame:
            unknown.add(fn)
            return 0
        return frame[fn] + max((worst(g) for g in calls.get(fn, ())), default=0)

    return worst(root), sorted(unknown)


LABELS = (
    "vectors: files, rows",
    "flash: controller objects (text + data)",
    "library calls in them",
    "RAM: static in them (data + bss)",
    "RAM: the cycle's coefficients + state (the caller's)",
    "stack, one `mrs_step`: call graph / painted",
    "stack, one cycle: call graph / painted",
    "instructions, `mrs_step`: typical (median) / worst",
    "instructions, one cycle: typical (median) / worst",
    "stated clock",
    "worst cycle at 1 instruction per clock (a lower bound): time, share of 2 ms",
)


def column(core: Core, build: Path, r: Results) -> list[str]:
    """One core's cells, in the order of LABELS."""
    text, data, bss = sizes(build)
    law_stack, cycle_stack = static_stack(build, "mrs_step")[0], static_stack(build, "cycle")
    helpers = " (call graph: + libgcc's soft-float helpers)" if cycle_stack[1] else ""
    law, cycle = r.counts["law"], r.counts["cycle"]
    worst_s = max(cycle) / core.clock_hz
    return [
        f"{len(r.lines)}, {r.steps}: " + ("bit for bit (every difference 0)" if core.exact
                                           else "line for line the x86-64 float32 build's"),
        f"{text + data} B",
        ", ".join(f"`{s}`" for s in library_calls(build)) or "none",
        f"{data + bss} B",
        f"{r.stack['coeffs_bytes']} + {r.stack['state_bytes']} B",
        f"{law_stack} / {r.stack['law_stack']} B",
        f"{cycle_stack[0]} / {r.stack['cycle_stack']} B{helpers}",
        f"{int(statistics.median(law))} / {max(law)}",
        f"{int(statistics.median(cycle))} / {max(cycle)}",
        f"{core.clock_hz / 1e6:g} MHz",
        f"{worst_s * 1e6:.2f} µs, {worst_s / PERIOD_S * 100:.2f} %",
    ]


def table(build: Path, cores: list[Core], results: dict[str, Results]) -> str:
    columns = [column(c, build / c.name, results[c.name]) for c in cores]
    head = "| | " + " | ".join(c.title for c in cores) + " |\n|---|" + "---|" * len(cores) + "\n"
    return head + "".join(f"| {label} | " + " | ".join(col[i] for col in columns) + " |\n"
                          for i, label in enumerate(LABELS))


def render(doc: str, body: str) -> str:
    start, end = doc.index(BEGIN) + len(BEGIN), doc.index(END, doc.index(BEGIN))
    return doc[:start] + "\n" + body + doc[end:]


def main(argv: list[str] | None = None) -> int:
    parser = Parser(description="Check the PIL target's vectors; print its budget table.")
    parser.add_argument("build", type=Path, help="the target's build directory (ports/c/build/pil)")
    parser.add_argument("cores", nargs="+", help="cores run: " + ", ".join(CORES))
    parser.add_argument("--vectors", type=Path, default=VECTORS, metavar="DIR",
                        help="the vector files the target ran (default: tests/vectors)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--write", type=Path, metavar="DOC", help="write the table into DOC")
    group.add_argument("--check", type=Path, metavar="DOC", help="fail if DOC's table is not this one")
    args = parser.parse_args(argv)
    unknown = [c for c in args.cores if c not in CORES]
    if unknown:
        parser.error(f"unknown core {unknown[0]!r} (known: {', '.join(CORES)})")
    cores = [CORES[c] for c in args.cores]
    try:
        results = {c.name: read_results(args.build / c.name / "results.txt") for c in cores}
    except OSError as exc:
        print(f"pil: no results: {exc.strerror}: {exc.filename} (make -C ports/c pil)", file=sys.stderr)
        return 2
    failures = [f for c in cores for f in verdicts(c, results[c.name], args.vectors)
                + stack_verdicts(c, args.build / c.name, results[c.name])]
    for f in failures:
        print(f, file=sys.stderr)
    if failures:
        return 1
    body = table(args.build, cores, results)
    for c in cores:
        print(f"pil {c.name}: {len(results[c.name].lines)} vector files, {results[c.name].steps} rows: pass")
    print(body, end="")
    doc = args.write or args.check
    if doc is not None:
        text = doc.read_text(encoding="utf-8")
        if args.write:
            doc.write_text(render(text, body), encoding="utf-8")
        elif render(text, body) != text:
            print(f"pil: {doc}'s budget table is stale: run `{COMMAND}`", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
