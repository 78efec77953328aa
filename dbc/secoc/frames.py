"""What an authenticated frame holds and the one way a frame is signed, shared by the command
(``command``) and the sensor frames (``sensors``); and the two shapes the link
(``mrsteer_dbc.link``) sees every signer and verifier in.

Each authenticated message carries, besides its data and E2E fields, the low bit of the
freshness epoch (``*_FvEpoch``), the low bits of the per-epoch message counter (``*_FvCounter``)
and the leading bits of the CMAC (``*_MAC``).  The MAC covers the frame ID, the payload with
the E2E CRC byte and the MAC bits zero, and the full 64-bit freshness value; the sender sets the
MAC first and the E2E CRC last, so the CRC covers the authenticator too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Protocol

from mrsteer_dbc.contract import Contract
from mrsteer_dbc.secoc.cmac import TruncatedCmac, frame_mac, freshness
from mrsteer_dbc.secoc.keys import SecOCError


@dataclass(frozen=True)
class AuthFields:
    """The SecOC fields of one authenticated message, as the DBC defines them."""

    name: str
    frame_id: int
    alive: str  # the E2E alive-counter signal
    epoch_bit: str
    counter_low: str
    counter_low_bits: int
    mac: str
    mac_bits: int
    mac_start: int  # the MAC's first bit (little-endian): its place in the payload read as one integer
    zero_mask: bytes  # AND mask clearing the CRC byte and the MAC bits

    @classmethod
    def of(cls, contract: Contract, name: str, purpose: str = "SecOC",
           counter_low_bits: int | None = None) -> "AuthFields":
        """The fields of message ``name``; ``counter_low_bits`` the FV counter width required
        (any if None); ``purpose`` names the feature in the errors."""
        try:
            msg = contract.message(name)
        except KeyError:
            raise SecOCError(f"the DBC has no {name} message: {purpose} needs it") from None
        e2e = contract.e2e(name)
        if e2e is None:
            raise SecOCError(f"{name} must be E2E-protected: {purpose} uses its alive counter")
        stem = name.removeprefix("MRS_")
        sigs = {}
        for suffix, bits in (("FvEpoch", 1), ("FvCounter", counter_low_bits), ("MAC", None)):
            try:
                s = msg.get_signal_by_name(f"{stem}_{suffix}")
            except KeyError:
                raise SecOCError(f"{name} has no {stem}_{suffix} signal: {purpose} needs it") from None
            if (bits is not None and s.length != bits) or s.byte_order != "little_endian":
                raise SecOCError(f"{s.name} must be a little-endian {bits or s.length}-bit field")
            sigs[suffix] = s
        mac = sigs["MAC"]
        if not 0 < mac.length <= 128:
            raise SecOCError(f"{mac.name}: MAC width out of range")
        # Every payload bit is authenticated but the CRC's and the MAC's own, spare bits too: a
        # forger must not be able to flip even a bit that no receiver reads today.
        mask = bytearray(b"\xff" * msg.length)
        mask[e2e.crc_byte] = 0
        for bit in range(mac.start, mac.start + mac.length):
            mask[bit // 8] &= ~(1 << (bit % 8)) & 0xFF
        return cls(name, msg.frame_id, e2e.counter_signal, sigs["FvEpoch"].name, sigs["FvCounter"].name,
                   sigs["FvCounter"].length, mac.name, mac.length, mac.start, bytes(mask))

    def zeroed(self, data: bytes) -> bytes:
        """The payload the MAC covers: every byte, with the CRC and the MAC zero."""
        return bytes(b & m for b, m in zip(data, self.zero_mask))

    def write_mac(self, data: bytearray, mac: int) -> bytearray:
        """Put ``mac`` into the (zero) MAC field of ``data``, in place."""
        word = int.from_bytes(data, "little") | (mac << self.mac_start)
        data[:] = word.to_bytes(len(data), "little")
        return data


def sign_frame(contract: Contract, cmac: TruncatedCmac, f: AuthFields, values: Mapping[str, float | str],
               alive: int, fresh: tuple[int, int] | None, *, strict: bool = True) -> bytes:
    """The frame of ``f``'s message, encoded once: FV fields for ``fresh`` = (epoch, counter),
    the MAC over the payload with CRC and MAC zero, the E2E CRC last.  Without freshness
    (``fresh`` None) the frame is only E2E-protected and its SecOC fields are 0."""
    if fresh is None:
        return contract.encode(f.name, values, alive, strict=strict)
    epoch, counter = fresh
    full = dict(values)
    full[f.epoch_bit] = epoch & 1
    full[f.counter_low] = counter & ((1 << f.counter_low_bits) - 1)
    full[f.mac] = 0
    data = contract.encode_unsealed(f.name, full, alive, strict=strict)  # CRC and MAC zero, as the MAC wants
    mac = frame_mac(cmac, f.frame_id, bytes(data), freshness(epoch, counter), f.mac_bits)
    return contract.seal(f.name, f.write_mac(data, mac))


class FrameSigner(Protocol):
    """A sender's signer, as ``mrsteer_dbc.link.TxLink`` uses it."""

    fields: Mapping[str, AuthFields]  # the messages it signs

    def encode(self, name: str, values: Mapping[str, float | str], alive: int, *, strict: bool = True) -> bytes:
        """The frame, E2E-protected and, when the signer has freshness for it, authenticated."""
        ...


class FrameVerifier(Protocol):
    """A receiver's check of one message's authenticator, as ``mrsteer_dbc.link.RxLink`` uses it."""

    def verify(self, frame_id: int, data: bytes, signals: Mapping[str, float]) -> bool:
        """True if the frame is authentic and fresh (and its freshness then becomes the last
        accepted one).  ``data`` and ``signals`` come from a frame that passed
        ``Contract.decode`` (length, CRC, range)."""
        ...
