"""Output files written whole or not at all: a reader never sees half a file, and a failure
(disk full, say) leaves the directory as it was.  ``staged_directory`` does the same for a set
of outputs that takes long to make (a directory of runs)."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator, Mapping

_UMASK = os.umask(0)
os.umask(_UMASK)
_FILE_MODE = 0o666 & ~_UMASK  # mkstemp creates 0600; outputs get ordinary permissions


def write_files(directory: Path, files: Mapping[str, str | bytes]) -> list[Path]:
    """Write every file whole, or none of them: each goes to a temporary file in ``directory``
    first, and only when all are written are they renamed into place.  A failure (disk full,
    say) removes the temporary files and leaves the directory as it was."""
    staged: list[tuple[str, str]] = []
    try:
        for name, data in files.items():
            fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{name}.", suffix=".tmp")
            staged.append((name, tmp))
            with os.fdopen(fd, "wb") as f:
                os.fchmod(f.fileno(), _FILE_MODE)
                f.write(data.encode() if isinstance(data, str) else data)
        for name, tmp in staged:
            os.replace(tmp, directory / name)
    except BaseException:
        for _, tmp in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise
    return [directory / name for name in files]


def write_atomic(path: Path, data: str | bytes) -> None:
    """One file, whole or not at all (``write_files``)."""
    write_files(path.parent, {path.name: data})


def make_dirs(path: Path) -> list[Path]:
    """Create ``path`` and its missing parents; the ones created, deepest first (for
    ``remove_empty``: an output that failed leaves the tree as it was)."""
    missing = [d for d in (path, *path.parents) if not d.exists()]
    path.mkdir(parents=True, exist_ok=True)
    return missing


def remove_empty(created: list[Path]) -> None:
    """Remove the directories ``make_dirs`` created, deepest first, while they are empty."""
    for d in created:
        try:
            d.rmdir()  # only if empty
        except OSError:
            break  # its parents hold it


@contextlib.contextmanager
def staged_directory(target: Path) -> Iterator[Path]:
    """A scratch directory beside ``target`` to make a set of outputs in.  When the block ends
    without an error, each of its entries replaces ``target``'s entry of that name (others in
    ``target`` are kept; ``target`` is created if need be); on an error, Ctrl-C included, it is
    removed and ``target`` is as it was (the parents made for it removed).  Nothing is moved into
    place before the whole set exists."""
    if target.exists() and not target.is_dir():
        raise ValueError(f"--out {target} exists and is not a directory")
    created = make_dirs(target.parent)
    stage = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    try:
        yield stage
        target.mkdir(exist_ok=True)
        _swap_in(stage, target)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        remove_empty(created)
        raise
    shutil.rmtree(stage, ignore_errors=True)


def _swap_in(stage: Path, target: Path) -> None:
    """Move ``stage``'s entries into ``target``; the entries they replace go to ``stage`` first
    (removed with it), and come back if a move fails."""
    old = stage / ".replaced"
    old.mkdir()
    new = [e for e in sorted(stage.iterdir()) if e != old]
    moved: list[str] = []
    try:
        for entry in new:
            if os.path.lexists(target / entry.name):
                os.replace(target / entry.name, old / entry.name)
            os.replace(entry, target / entry.name)
            moved.append(entry.name)
    except BaseException:
        for name in moved:
            with contextlib.suppress(OSError):
                os.replace(target / name, stage / name)
        for entry in old.iterdir():
            with contextlib.suppress(OSError):
                os.replace(entry, target / entry.name)
        raise
