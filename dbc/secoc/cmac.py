"""The authenticator and the freshness value: truncated AES-128-CMAC over frame ID, payload and
a 64-bit freshness value (FV = epoch << 24 | per-epoch message counter)."""

from __future__ import annotations

from mrsteer_dbc.secoc.keys import KEY_BYTES, SecOCError

COUNTER_BITS = 24  # the message counter's share of the 64-bit freshness value


class TruncatedCmac:
    """AES-128-CMAC (NIST SP 800-38B, RFC 4493), keeping the leading ``bits`` bits."""

    def __init__(self, key: bytes) -> None:
        if len(key) != KEY_BYTES:
            raise SecOCError(f"the SecOC key must be {KEY_BYTES} bytes, got {len(key)}")
        # Imported here: processes that do not authenticate need not load OpenSSL.
        from cryptography.hazmat.primitives.ciphers import algorithms
        from cryptography.hazmat.primitives.cmac import CMAC

        self._base = CMAC(algorithms.AES(key))  # the key schedule once; copied per message

    def __deepcopy__(self, memo: dict[int, object]) -> "TruncatedCmac":
        """Itself: it holds no state that changes (each MAC works on a copy of the key schedule),
        and OpenSSL's objects cannot be copied (a replay copies whole nodes)."""
        return self

    def __call__(self, data: bytes, bits: int) -> int:
        c = self._base.copy()
        c.update(data)
        return int.from_bytes(c.finalize(), "big") >> (128 - bits)


def freshness(epoch: int, counter: int) -> int:
    """The full 64-bit freshness value."""
    return (epoch << COUNTER_BITS) | counter


def epoch_named(bit: int, current: int | None, previous: int | None) -> int | None:
    """The epoch a frame's FV epoch bit names: the current one if the low bits agree, else the
    one before (a sync may still be in flight)."""
    return current if current is not None and (current & 1) == bit else previous


def frame_mac(cmac: TruncatedCmac, frame_id: int, zeroed: bytes, fv: int, bits: int) -> int:
    """The authenticator of one frame: CMAC over frame ID || payload (CRC and MAC zero) || FV."""
    return cmac(frame_id.to_bytes(2, "big") + zeroed + fv.to_bytes(8, "big"), bits)
