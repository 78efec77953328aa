"""Output files written whole or not at all: a reader never sees half a file, and a failure
(disk full, say) leaves the directory as it was."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Mapping

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
