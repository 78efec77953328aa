"""The port on a Cortex-M under QEMU (docs/porting.md, "On a Cortex-M"): every golden vector on
both cores, the budget table in the doc is what the target gives, the emulator's instruction
count re-derived from QEMU's own execution log, and bad input (a vector file that does not parse,
a core the target does not know) is one line and a non-zero exit."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PORT = ROOT / "ports" / "c"
PIL = PORT / "build" / "pil"
DOC = ROOT / "docs" / "porting.md"
VECTORS = ROOT / "tests" / "vectors"
# The vector file whose counts the execution log re-derives: the shortest with faults and recovery.
CROSS_CHECK = VECTORS / "limited_100hz_m2_ratelimit__faults_and_recovery.csv"
TOOLS = ("arm-none-eabi-gcc", "qemu-system-arm", "make")
QEMU_M7 = ["qemu-system-arm", "-M", "mps2-an500", "-nographic", "-monitor", "none", "-serial", "none"]

pytestmark = pytest.mark.skipif(any(shutil.which(t) is None for t in TOOLS),
                                reason="the Cortex-M target needs gcc-arm-none-eabi, libnewlib-arm-none-eabi and "
                                       "qemu-system-arm (.ci/run installs them)")


def _make(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["make", "-s", "-C", str(PORT), f"PYTHON={sys.executable}", *args], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def pil() -> str:
    """`make -C ports/c pil` (nothing to redo when .ci/run has just run it): its output."""
    proc = _make("pil")
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _budget(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(PORT / "pil" / "budget.py"), str(PIL), "m4f", "m7", *args],
                          capture_output=True, text=True, timeout=120)


def test_every_vector_passes_on_both_cores(pil: str) -> None:
    files = len(list(VECTORS.glob("*__*.csv")))
    for core in ("m4f", "m7"):
        assert re.search(rf"^pil {core}: {files} vector files, \d+ rows: pass$", pil, re.M), pil
    m7 = (PIL / "m7" / "results.txt").read_text(encoding="utf-8")
    runs = re.findall(r"^steps=.*$", m7, re.M)
    assert len(runs) == files
    for line in runs:  # float64 on the M7: the Python firmware's numbers, every one
        figures = dict(re.findall(r"(\w+)=(\S+)", line))
        assert figures["real_bytes"] == "8"
        assert all(float(v) == 0 for k, v in figures.items() if k.endswith(("_err", "_mismatch"))), line
    m4f = (PIL / "m4f" / "results.txt").read_text(encoding="utf-8")
    assert all("real_bytes=4" in line for line in re.findall(r"^steps=.*$", m4f, re.M))


def test_the_budget_table_in_the_doc_is_what_the_target_gives(pil: str) -> None:
    proc = _budget("--check", str(DOC))
    assert proc.returncode == 0, f"docs/porting.md's table is stale: run `make -C ports/c pil-table`\n{proc.stderr}"


def test_a_hand_edited_budget_is_found(pil: str, tmp_path: Path) -> None:
    doc = tmp_path / "porting.md"
    text = DOC.read_text(encoding="utf-8")
    edited = re.sub(r"(\| instructions, `mrs_step`: typical \(median\) / worst \| )(\d+)",
                    lambda m: m.group(1) + str(int(m.group(2)) + 1), text)
    assert edited != text
    doc.write_text(edited, encoding="utf-8")
    proc = _budget("--check", str(doc))
    assert proc.returncode == 1 and proc.stderr.count("\n") == 1 and "stale" in proc.stderr, proc.stderr
    assert _budget("--write", str(doc)).returncode == 0
    assert doc.read_text(encoding="utf-8") == text


def _marker_counts(log: str, pcs: dict[int, str]) -> list[tuple[str, int]]:
    """(name, instructions) per marker pair from an execution log of one line per instruction."""
    out, opened = [], {}
    executed = [int(m.group(1), 16) for m in re.finditer(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/", log, re.M)]
    for i, pc in enumerate(executed):
        name = pcs.get(pc)
        if name is None:
            continue
        kind, edge = name.rsplit("_", 1)
        if edge == "begin":
            opened[kind] = i
        elif kind in opened:
            out.append((kind, i - opened.pop(kind) - 2))  # less the begin's `bx lr` and the `bl` to the end
    return out


def test_the_instruction_count_is_the_emulators_own_log(pil: str, tmp_path: Path) -> None:
    """The plugin's counts of one vector file on the M7, re-derived from QEMU's `-d exec` log with
    one instruction per translation block, logged only inside the measured code (-dfilter)."""
    elf = PIL / "m7" / "pil.elf"
    symbols = subprocess.run(["arm-none-eabi-nm", "-S", "--defined-only", str(elf)], capture_output=True, text=True,
                             check=True).stdout
    measured = set(subprocess.run(["arm-none-eabi-nm", "--defined-only", *(str(PIL / "m7" / f"{o}.o") for o in
                                   ("mrs_controller", "mrs_cycle", "mrs_monitor", "mrs_e2e"))],
                                  capture_output=True, text=True, check=True).stdout.split())
    ranges, pcs = [], {}
    for line in symbols.splitlines():
        parts = line.split()
        if len(parts) != 4 or parts[2].lower() != "t":
            continue
        addr, size, name = int(parts[0], 16) & ~1, int(parts[1], 16), parts[3]
        if name.startswith("pil_") and name.endswith(("_begin", "_end")):
            pcs[addr] = name.removeprefix("pil_")
        if name in measured or name in ("main", "step", "cycle") or addr in pcs:
            ranges.append(f"0x{addr:x}+0x{size:x}")
    assert len(pcs) == 4
    log = tmp_path / "exec.log"
    cfg = VECTORS / (CROSS_CHECK.name.split("__")[0] + ".cfg")
    subprocess.run([*QEMU_M7, "-kernel", str(elf), "-semihosting-config",
                    f"enable=on,target=native,arg=pil,arg={cfg},arg={CROSS_CHECK}", "-singlestep",
                    "-d", "exec,nochain", "-dfilter", ",".join(ranges), "-D", str(log)],
                   capture_output=True, text=True, timeout=300, check=True)
    from_log = _marker_counts(log.read_text(encoding="utf-8"), pcs)
    results = (PIL / "m7" / "results.txt").read_text(encoding="utf-8")
    section = results.split(f"file {CROSS_CHECK.name}\n", 1)[1].split("\nfile ", 1)[0]
    from_plugin = [(k, int(n)) for k, n in re.findall(r"^(law|cycle) (\d+)$", section, re.M)]
    assert len(from_plugin) > 200 and from_log == from_plugin


def test_a_vector_file_that_does_not_parse_is_one_line_and_exit_2(pil: str, tmp_path: Path) -> None:
    cfg = VECTORS / (CROSS_CHECK.name.split("__")[0] + ".cfg")
    rows = CROSS_CHECK.read_text(encoding="utf-8").splitlines()
    rows[5] = rows[5].replace(",", ";", 3)
    bad = tmp_path / CROSS_CHECK.name
    bad.write_text("\n".join(rows) + "\n", encoding="utf-8")
    proc = subprocess.run([*QEMU_M7, "-kernel", str(PIL / "m7" / "pil.elf"), "-semihosting-config",
                           f"enable=on,target=native,arg=pil,arg={cfg},arg={bad}"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and proc.stdout == "", proc.stdout
    assert proc.stderr == f"run_vectors: malformed row in: {bad}\n"
    # and through make: the target's line, and the make fails
    (tmp_path / cfg.name).write_bytes(cfg.read_bytes())
    proc = _make("pil", "PIL_CORES=m7", f"VECTORS={tmp_path}", f"PIL={tmp_path / 'pil'}")
    assert proc.returncode != 0 and f"run_vectors: malformed row in: {bad}" in proc.stderr, proc.stderr


def test_a_core_the_target_does_not_know_is_one_line_and_a_failure() -> None:
    proc = _make("pil", "PIL_CORES=m33")
    assert proc.returncode != 0 and proc.stderr.count("\n") == 1, proc.stderr
    assert "unknown core 'm33' (known: m4f m7)" in proc.stderr
    proc = subprocess.run([sys.executable, str(PORT / "pil" / "budget.py"), str(PIL), "m33"], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "unknown core 'm33'" in proc.stderr
