"""The commands the README and ``docs/*.md`` show, read from their ``sh`` and ``python`` blocks,
and how to run them as a new user would: from a copy of the repository, with the project's
virtual environment activated (the README's ``. .venv/bin/activate``) and ``MRSTEER_QUICK=1``
(every long command's short run, as the README says).

A block the suite cannot run (it needs root, or a kernel with CAN, or it is the suite itself)
says so in an HTML comment on the line before its fence, with the reason::

    <!-- doc-test: skip: REASON -->

A block either needs the machine to itself (``needs_quiet_machine``: a realtime loop, a
benchmark, anything not known to be offline) or is offline (it computes, or runs the bus in
lockstep, and its result does not depend on the machine's load).  The quiet blocks run one at a
time in one copy of the repository, in the docs' order, so such a block may use what an earlier
one wrote; the offline blocks run beside other tests in a copy of their own, each using only
what it writes itself.  Inline code spans are prose:
one that holds a whole command line with arguments and no placeholder must also appear in a
block (``inline_commands_outside_blocks``), so that what a reader would type is run.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from firmware_py.platform.cli import QUICK_ENV

ROOT = Path(__file__).resolve().parents[1]
DOCS = (ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")))
LANGUAGES = ("sh", "python")  # a python block runs as one script
#: The longest a block may run before it counts as hung.
BLOCK_TIMEOUT_S = 900.0

_FENCE = re.compile(r"^```(\S*)\s*$")
_TAG = re.compile(r"^<!--\s*doc-test:\s*(?P<tag>skip)(?::\s*(?P<reason>.+?))?\s*-->\s*$")
_INLINE = re.compile(r"`([^`\n]+)`")
_COMMAND_START = re.compile(r"^(mrsteer|make|cantools|candump|cansend|sudo|python -m|ports/c/build/\S+|tools/\S+)\s")
#: An inline span with one of these is a pattern, not a command: FILE, DIR, [--json], a|b, ...
_PLACEHOLDER = re.compile(r"(?<![-\w])[A-Z][A-Z0-9_]*\b|[\[\]|…]|\.\.\.|\d/rate")


@dataclass(frozen=True)
class Block:
    """One ``sh`` block: where it is, its command lines (comments and blank lines dropped), its
    tag and the tag's reason."""

    path: Path
    line: int
    commands: tuple[str, ...]
    tag: str | None = None
    reason: str = ""

    @property
    def name(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"

    @property
    def script(self) -> str:
        return "\n".join(self.commands) + "\n"


def blocks(path: Path) -> list[Block]:
    """The ``sh`` blocks of one Markdown file, in order."""
    out: list[Block] = []
    lines = path.read_text().splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        start, lang = i, m.group(1)
        i += 1
        body: list[str] = []
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        i += 1
        if lang not in LANGUAGES:
            continue
        tag_match = _TAG.match(lines[start - 1]) if start > 0 else None
        commands = tuple(s for s in body if s.strip() and not s.lstrip().startswith("#")) if lang == "sh" \
            else ("python - <<'PYTHON'", *body, "PYTHON")
        out.append(Block(path, start + 1, commands, tag_match and tag_match["tag"],
                         (tag_match and tag_match["reason"]) or ""))
    return out


def all_blocks() -> list[Block]:
    return [b for doc in DOCS for b in blocks(doc)]


#: Commands whose outcome does not depend on the machine's load: computation, file tools, and
#: ``hil run`` in its default lockstep mode (the plant waits for each command).  Anything else (a
#: realtime run, a benchmark, the fault matrix, the bus nodes, ``make demo``) needs the machine.
_OFFLINE = re.compile(r"^(\. \.venv/bin/activate|export \w+=.*|python( -m cantools)? .*|cantools .*|dask .*"
                      r"|make paper|make -C ports/c (check|node)|ports/c/build/mrs_node --help"
                      r"|mrsteer (--help|design|sim|campaign|replay|hil evidence)\b.*"
                      r"|mrsteer hil run\b(?!.*--mode realtime)(?!.*--controller-cmd).*)$")


def needs_quiet_machine(block: Block) -> bool:
    """Whether a block must run alone: some command of it is not known to be offline."""
    if block.commands and block.commands[0].startswith("python - <<"):
        return False  # a script: the firmware in-process
    return not all(_OFFLINE.match(_strip_comment(c)) for c in block.commands)


def inline_commands_outside_blocks() -> list[str]:
    """Inline code spans that are whole command lines (with a flag, a ``make`` target or a
    redirection) and no placeholder, and that no ``sh`` block of the docs holds: ``file:line:
    span`` each."""
    shown = {_strip_comment(c) for b in all_blocks() for c in b.commands}
    missing = []
    for doc in DOCS:
        in_fence = False
        for number, line in enumerate(doc.read_text().splitlines(), 1):
            if line.startswith("```"):
                in_fence = not in_fence
                continue
            if in_fence:
                continue
            for span in _INLINE.findall(line):
                args = re.sub(r"^python -m \S+", "", span)
                whole = " -" in args or span.startswith("make ") or " < " in span or " > " in span
                if _COMMAND_START.match(span) and whole and not _PLACEHOLDER.search(span) and span not in shown:
                    missing.append(f"{doc.relative_to(ROOT)}:{number}: {span}")
    return missing


def _strip_comment(command: str) -> str:
    """A command line without its trailing ``# comment`` and spaces."""
    return re.sub(r"\s+#\s.*$", "", command).strip()


def repo_copy(dest: Path) -> Path:
    """The repository's files as a clone would have them once committed (``git ls-files``:
    tracked and new files, not ignored ones: no outputs, builds or environments), in ``dest``,
    with a ``.venv`` linked to the environment running the tests and whose install stamp
    is newer than ``pyproject.toml``: ``make`` finds it installed and installs nothing (an
    install from the copy would point the environment at it)."""
    listed = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    venv = dest / ".venv"
    venv.mkdir()
    # bin, and lib and pyvenv.cfg too: ``.venv/bin/python`` (the Makefile's) finds its
    # environment's packages from the folder it is in.
    for entry in Path(sys.prefix).iterdir():
        if entry.name != ".installed":
            (venv / entry.name).symlink_to(entry)
    stamp = venv / ".installed"
    stamp.touch()
    older = stamp.stat().st_mtime - 1.0
    os.utime(dest / "pyproject.toml", (older, older))
    return dest


def environment() -> dict[str, str]:
    """The environment of a user who activated the project's virtual environment."""
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.prefix) / "bin") + os.pathsep + env.get("PATH", "")
    env["VIRTUAL_ENV"] = sys.prefix
    env[QUICK_ENV] = "1"
    env.pop("PYTHONHOME", None)
    return env


#: Bash around a block: stop at the first failing line and name it; end the block's background
#: jobs (``mrsteer bus &``) when it ends.
_PROLOGUE = """set -eo pipefail
trap 'status=$?; echo "doc-test: failed (exit $status): $BASH_COMMAND" >&2; exit $status' ERR
trap 'status=$?; trap - ERR; running=$(jobs -p); [ -z "$running" ] || kill $running 2>/dev/null || true; wait 2>/dev/null || true; exit $status' EXIT
"""


def run(block: Block, cwd: Path, timeout: float = BLOCK_TIMEOUT_S) -> subprocess.CompletedProcess[str]:
    """Run a block's commands as one bash script in ``cwd``."""
    return subprocess.run(["bash", "-c", _PROLOGUE + block.script], cwd=cwd, env=environment(), text=True,
                          capture_output=True, timeout=timeout)
