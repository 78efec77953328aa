"""Optional authentication of ``MRS_AuxSteerCmd`` in the style of AUTOSAR SecOC.

E2E protection (CRC and alive counter) catches corruption, not forgery: its data IDs are in the
DBC, so anyone on the bus can send a command with a valid CRC and the next counter.  With a
shared 128-bit key, the controller adds to every command a truncated AES-CMAC over the frame ID,
the payload and a 64-bit freshness value (FV), and the actuator applies only commands whose MAC
verifies for a FV newer than the last one it accepted.

**Freshness** (the AUTOSAR freshness-value-manager pattern with the actuator as FV master):

* FV = epoch (40 bits) << 24 | message counter (24 bits).
* The actuator (``CommandVerifier``) issues the epoch in ``MRS_SecOCSync`` every 100 ms
  (its DBC cycle time), authenticated by its own 24-bit MAC.  Each new epoch is larger than the
  last and than the milliseconds since 2026-01-01 UTC, with the opposite low bit: a restarted
  actuator never reissues an epoch (a real ECU would keep a trip counter in NVM instead of the
  clock).
* The controller (``CommandSigner``) adopts an authentic sync only if its epoch is newer than
  the one it has, restarts its message counter at 0, and sends per command the epoch's low bit
  and the counter's low 4 bits.
* The actuator reconstructs the full FV: the epoch is its current one or the one before (the
  low bit says which; a sync may still be in flight), the counter the smallest value after the
  last accepted one with the sent low bits.

**Bit budget on classic CAN** (8 data bytes): the command's data take 42 bits (CRC 8, counter 4,
state 2, angle 24, measurement counter 4); the other 22 hold the FV's 1 + 4 bits and a 16-bit
MAC (1 bit spare).  The DLC grew from 6 to 8 bytes for it: +2.0 points of worst-case bus load at
500 Hz and 500 kbit/s, and the sync +0.27 (36.9 % to 39.2 % in all).  A 16-bit MAC gives a
blind forger a 2^-16 chance per frame; every failure is counted by the actuator (a vehicle would
act on the count).  A longer MAC needs a second frame (an 8-byte authenticator at 500 Hz is
another 13.5 % load).

**Limits** (what the truncated FV cannot do): after more than 15 consecutive lost commands the
counter's low bits are ambiguous and commands fail until the next epoch (at most one sync
period, 100 ms, later); a restarted controller's commands verify from the next epoch on, or as
soon as its counter passes the old instance's; a frame withheld and sent later is accepted if
nothing newer was accepted meanwhile and its epoch is at most one old (about 200 ms).

Authenticated data (big-endian): command: frame ID (2 bytes) || the 8 payload bytes with the E2E
CRC and the MAC fields zero || FV (8 bytes).  Sync: frame ID (2 bytes) || epoch (8 bytes).  The
MAC is the leading bits of the 128-bit CMAC.  The sender sets the MAC first and the E2E CRC
last, so the CRC covers the authenticator too; the receiver checks E2E length and CRC, then the
MAC, and only then the alive-counter sequence, so a forged frame cannot advance the sequence.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

from mrsteer_dbc import Contract, ContractError

COMMAND = "MRS_AuxSteerCmd"
SYNC = "MRS_SecOCSync"
KEY_ENV = "MRSTEER_SECOC_KEY"  # 32 hex digits
KEY_BYTES = 16
COUNTER_BITS = 24  # the message counter's share of the 64-bit freshness value
EPOCH_ORIGIN_S = 1767225600  # 2026-01-01T00:00:00Z: the epochs are milliseconds after it


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


class TruncatedCmac:
    """AES-128-CMAC (NIST SP 800-38B, RFC 4493), keeping the leading ``bits`` bits."""

    def __init__(self, key: bytes) -> None:
        if len(key) != KEY_BYTES:
            raise SecOCError(f"the SecOC key must be {KEY_BYTES} bytes, got {len(key)}")
        # Imported here: processes that do not authenticate need not load OpenSSL.
        from cryptography.hazmat.primitives.ciphers import algorithms
        from cryptography.hazmat.primitives.cmac import CMAC

        self._base = CMAC(algorithms.AES(key))  # the key schedule once; copied per message

    def __call__(self, data: bytes, bits: int) -> int:
        c = self._base.copy()
        c.update(data)
        return int.from_bytes(c.finalize(), "big") >> (128 - bits)


@dataclass(frozen=True)
class Layout:
    """The SecOC fields, as the DBC defines them."""

    cmd_id: int
    sync_id: int
    crc_signal: str
    epoch_bit: str  # AuxSteerCmd_FvEpoch
    counter_low: str  # AuxSteerCmd_FvCounter
    counter_low_bits: int
    mac: str
    mac_bits: int
    sync_epoch: str
    sync_epoch_bits: int
    sync_mac: str
    sync_mac_bits: int

    @classmethod
    def of(cls, contract: Contract) -> "Layout":
        try:
            cmd, sync = contract.message(COMMAND), contract.message(SYNC)
        except KeyError as exc:
            raise SecOCError(f"the DBC has no {exc.args[0]} message: SecOC needs it") from None

        def sig(msg: object, suffix: str) -> tuple[str, int]:
            name = f"{msg.name.removeprefix('MRS_')}_{suffix}"
            try:
                s = msg.get_signal_by_name(name)
            except KeyError:
                raise SecOCError(f"{msg.name} has no {name} signal: SecOC needs it") from None
            return s.name, s.length

        e2e = contract.e2e(COMMAND)
        if e2e is None:
            raise SecOCError(f"{COMMAND} must be E2E-protected")
        epoch_bit, n_epoch = sig(cmd, "FvEpoch")
        if n_epoch != 1:
            raise SecOCError(f"{epoch_bit} must be 1 bit, got {n_epoch}")
        counter_low, n_counter = sig(cmd, "FvCounter")
        mac, n_mac = sig(cmd, "MAC")
        sync_epoch, n_sync_epoch = sig(sync, "Epoch")
        sync_mac, n_sync_mac = sig(sync, "MAC")
        if not (0 < n_counter < COUNTER_BITS and 0 < n_sync_epoch <= 64 - COUNTER_BITS
                and 0 < n_mac <= 128 and 0 < n_sync_mac <= 128):
            raise SecOCError("SecOC field widths out of range in the DBC")
        return cls(cmd.frame_id, sync.frame_id, e2e.crc_signal, epoch_bit, counter_low, n_counter, mac, n_mac,
                   sync_epoch, n_sync_epoch, sync_mac, n_sync_mac)


def freshness(epoch: int, counter: int) -> int:
    """The full 64-bit freshness value."""
    return (epoch << COUNTER_BITS) | counter


class _Peer:
    def __init__(self, contract: Contract, key: bytes) -> None:
        try:
            self.layout = Layout.of(contract)
        except ContractError as exc:
            raise SecOCError(str(exc)) from None
        self.contract = contract
        self._cmac = TruncatedCmac(key)
        self._cmd = contract.message(COMMAND)
        self._sync = contract.message(SYNC)

    def sync_mac(self, epoch: int) -> int:
        lay = self.layout
        return self._cmac(lay.sync_id.to_bytes(2, "big") + epoch.to_bytes(8, "big"), lay.sync_mac_bits)

    def command_mac(self, zeroed: bytes, fv: int) -> int:
        """MAC of a command payload whose CRC and MAC fields are zero."""
        lay = self.layout
        return self._cmac(lay.cmd_id.to_bytes(2, "big") + zeroed + fv.to_bytes(8, "big"), lay.mac_bits)


class CommandSigner(_Peer):
    """Controller side: learns the epoch from authentic syncs and signs each command."""

    def __init__(self, contract: Contract, key: bytes) -> None:
        super().__init__(contract, key)
        self.epoch: int | None = None
        self.counter = 0
        self.syncs_accepted = 0
        self.syncs_rejected = 0

    @property
    def synced(self) -> bool:
        return self.epoch is not None and self.counter < (1 << COUNTER_BITS)

    def accept_sync(self, data: bytes) -> bool:
        """Adopt the epoch of an authentic sync newer than ours; False (and counted) otherwise.
        ``data`` must have passed ``Contract.decode`` (length)."""
        lay = self.layout
        raw = self._sync.decode(data, decode_choices=False, scaling=False)
        epoch = int(raw[lay.sync_epoch])
        if int(raw[lay.sync_mac]) != self.sync_mac(epoch) or (self.epoch is not None and epoch <= self.epoch):
            self.syncs_rejected += 1
            return False
        self.epoch, self.counter = epoch, 0
        self.syncs_accepted += 1
        return True

    def sign(self, values: Mapping[str, float | str], counter: int) -> bytes:
        """The command frame, E2E-protected and, once synced, authenticated (otherwise its SecOC
        fields are 0 and the actuator will reject it)."""
        if not self.synced:
            return self.contract.encode(COMMAND, values, counter)
        lay = self.layout
        assert self.epoch is not None
        full = dict(values)
        full[lay.epoch_bit] = self.epoch & 1
        full[lay.counter_low] = self.counter & ((1 << lay.counter_low_bits) - 1)
        full[lay.mac] = 0
        zeroed = bytearray(self.contract.encode(COMMAND, full, counter))
        zeroed[self.contract.e2e(COMMAND).crc_byte] = 0
        full[lay.mac] = self.command_mac(bytes(zeroed), freshness(self.epoch, self.counter))
        self.counter += 1
        return self.contract.encode(COMMAND, full, counter)


@dataclass
class VerifyStats:
    accepted: int = 0
    failed: int = 0  # MAC mismatch, unknown or stale freshness
    syncs_sent: int = 0


class CommandVerifier(_Peer):
    """Actuator side and freshness master: issues epochs and verifies commands."""

    def __init__(self, contract: Contract, key: bytes, clock: Callable[[], float] = time.time) -> None:
        super().__init__(contract, key)
        self._clock = clock
        self.current: int | None = None
        self.previous: int | None = None
        self.last: tuple[int, int] | None = None  # (epoch, counter) of the last accepted command
        self.stats = VerifyStats()

    def next_sync(self) -> bytes:
        """Start a new epoch and return the ``MRS_SecOCSync`` payload announcing it."""
        lay = self.layout
        epoch = max(int((self._clock() - EPOCH_ORIGIN_S) * 1000.0), 0)
        if self.current is not None:
            epoch = max(epoch, self.current + 1)
            if (epoch & 1) == (self.current & 1):
                epoch += 1
        if epoch >= 1 << lay.sync_epoch_bits:
            raise SecOCError("the freshness epoch overflowed its DBC field")
        self.previous, self.current = self.current, epoch
        self.stats.syncs_sent += 1
        return self.contract.encode(SYNC, {lay.sync_epoch: epoch, lay.sync_mac: self.sync_mac(epoch)})

    def verify(self, data: bytes) -> bool:
        """True if the command's MAC verifies for a freshness value newer than the last accepted
        one (which it then becomes).  ``data`` must have passed ``Contract.decode``."""
        lay = self.layout
        raw = self._cmd.decode(data, decode_choices=False, scaling=False)
        epoch = self.current if self.current is not None and (self.current & 1) == raw[lay.epoch_bit] else self.previous
        if epoch is None or (self.last is not None and epoch < self.last[0]):
            self.stats.failed += 1
            return False
        first = self.last[1] + 1 if self.last is not None and epoch == self.last[0] else 0
        window = 1 << lay.counter_low_bits
        counter = first + ((int(raw[lay.counter_low]) - first) % window)
        received = int(raw[lay.mac])
        raw[lay.mac] = 0
        raw[lay.crc_signal] = 0
        zeroed = self._cmd.encode(raw, scaling=False, strict=False)  # robust to any 8 bytes
        if counter >= 1 << COUNTER_BITS or self.command_mac(zeroed, freshness(epoch, counter)) != received:
            self.stats.failed += 1
            return False
        self.last = (epoch, counter)
        self.stats.accepted += 1
        return True
