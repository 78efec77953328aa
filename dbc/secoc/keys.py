"""The shared 128-bit SecOC key: from a file or ``$MRSTEER_SECOC_KEY``, and the error every
SecOC check raises for a bad key or a DBC without the authenticator fields."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

KEY_ENV = "MRSTEER_SECOC_KEY"  # 32 hex digits
KEY_BYTES = 16


class SecOCError(ValueError):
    """A missing or malformed key, or a contract without the authenticator fields."""


def load_key(path: Path | str | None = None, environ: Mapping[str, str] | None = None) -> bytes:
    """The 128-bit key from a file (32 hex digits, whitespace around them allowed) or, without a
    file, from ``$MRSTEER_SECOC_KEY``."""
    if path is not None:
        try:
            raw = Path(path).read_text(encoding="ascii")
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) else "not ASCII text"
            raise SecOCError(f"cannot read the SecOC key file {path}: {reason}") from None
        text, source = raw.strip(), f"key file {path}"
    else:
        text = (os.environ if environ is None else environ).get(KEY_ENV, "").strip()
        source = f"${KEY_ENV}"
        if not text:
            raise SecOCError(f"no SecOC key: give --secoc-key FILE or set {KEY_ENV} to 32 hex digits")
    try:
        key = bytes.fromhex(text)
    except ValueError:
        raise SecOCError(f"the SecOC key in {source} is not hexadecimal") from None
    if len(key) != KEY_BYTES:
        raise SecOCError(f"the SecOC key in {source} must be {KEY_BYTES} bytes (32 hex digits), got {len(key)}")
    return key
