"""Optional authentication of ``MRS_AuxSteerCmd`` and of the sensor frames in the style of
AUTOSAR SecOC (the sensor frames: ``SensorSigner``/``SensorVerifier``, further down).

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


def epoch_named(bit: int, current: int | None, previous: int | None) -> int | None:
    """The epoch a frame's FV epoch bit names: the current one if the low bits agree, else the
    one before (a sync may still be in flight)."""
    return current if current is not None and (current & 1) == bit else previous


def frame_mac(cmac: TruncatedCmac, frame_id: int, zeroed: bytes, fv: int, bits: int) -> int:
    """The authenticator of one frame: CMAC over frame ID || payload (CRC and MAC zero) || FV."""
    return cmac(frame_id.to_bytes(2, "big") + zeroed + fv.to_bytes(8, "big"), bits)


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
        return frame_mac(self._cmac, lay.cmd_id, zeroed, fv, lay.mac_bits)


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
        epoch = epoch_named(int(raw[lay.epoch_bit]), self.current, self.previous)
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


# --------------------------------------------------------------------------- sensor frames
#
# The same scheme in the other direction: the vehicle (the freshness master, which issues the
# epochs) signs its sensor frames, and the controller verifies them with the epochs it has taken
# from authentic syncs.  Classic CAN leaves no room for the command's 16-bit MAC and 4 FV bits:
# each sensor frame carries the epoch's low bit and the per-epoch counter's low 3 bits in the
# spare nibble of byte 1 and an 8-bit MAC in one extra byte.  The receiver recovers the counter
# from those 3 bits together with the E2E alive counter (mod 15): 8 and 15 are coprime, so the
# two residues fix the counter's advance modulo 120.  The verifier takes an advance of at most
# ``SENSOR_MAX_ADVANCE`` frames (up to 14 lost, more than the 10 that fault an input by timeout):
# a replayed frame up to 104 frames old is then refused before its MAC is even checked, and an
# 8-bit MAC that verifies by luck (1 in 256) moves the counter on by at most 15 frames.

SENSORS = ("MRS_DriverSteer", "MRS_YawRate", "MRS_VehicleSpeed")
_ALIVE_MODULO = 15  # the E2E alive counter: 0..14
SENSOR_FV_LOW_BITS = 3  # the per-epoch counter's bits on the wire: residues mod 8
_INV8_MOD15 = 2  # 8 * 2 = 16 = 1 (mod 15)
SENSOR_MAX_ADVANCE = 15


@dataclass(frozen=True)
class SensorFields:
    """The SecOC fields of one sensor message, as the DBC defines them."""

    name: str
    frame_id: int
    alive: str  # the E2E alive-counter signal
    epoch_bit: str
    counter_low: str
    mac: str
    mac_bits: int
    zero_mask: bytes  # AND mask clearing the CRC byte and the MAC bits

    @classmethod
    def of(cls, contract: Contract, name: str) -> "SensorFields":
        try:
            msg = contract.message(name)
        except KeyError:
            raise SecOCError(f"the DBC has no {name} message: sensor SecOC needs it") from None
        e2e = contract.e2e(name)
        if e2e is None:
            raise SecOCError(f"{name} must be E2E-protected: sensor SecOC uses its alive counter")
        stem = name.removeprefix("MRS_")
        sigs = {}
        for suffix, bits in (("FvEpoch", 1), ("FvCounter", SENSOR_FV_LOW_BITS), ("MAC", None)):
            try:
                s = msg.get_signal_by_name(f"{stem}_{suffix}")
            except KeyError:
                raise SecOCError(f"{name} has no {stem}_{suffix} signal: sensor SecOC needs it") from None
            if (bits is not None and s.length != bits) or s.byte_order != "little_endian":
                raise SecOCError(f"{s.name} must be a little-endian {bits}-bit field")
            sigs[suffix] = s
        mac = sigs["MAC"]
        if not 0 < mac.length <= 128:
            raise SecOCError(f"{mac.name}: MAC width out of range")
        mask = bytearray(b"\xff" * msg.length)
        mask[e2e.crc_byte] = 0
        for bit in range(mac.start, mac.start + mac.length):
            mask[bit // 8] &= ~(1 << (bit % 8)) & 0xFF
        return cls(name, msg.frame_id, e2e.counter_signal, sigs["FvEpoch"].name, sigs["FvCounter"].name,
                   mac.name, mac.length, bytes(mask))

    def zeroed(self, data: bytes) -> bytes:
        return bytes(b & m for b, m in zip(data, self.zero_mask))


def counter_advance(alive_delta: int, low_delta: int) -> int:
    """How far a sensor frame's FV counter is past the last accepted one (1..120), from the
    advance of the alive counter (mod 15) and of the FV counter's low 3 bits (mod 8)."""
    low = low_delta % 8
    k = (_INV8_MOD15 * (alive_delta - low)) % _ALIVE_MODULO
    advance = low + 8 * k
    return advance if advance else 8 * _ALIVE_MODULO


class _SensorPeer:
    def __init__(self, contract: Contract, key: bytes) -> None:
        try:
            self.fields = {name: SensorFields.of(contract, name) for name in SENSORS}
        except ContractError as exc:
            raise SecOCError(str(exc)) from None
        self.by_id = {f.frame_id: f for f in self.fields.values()}
        self.contract = contract
        self._cmac = TruncatedCmac(key)


class SensorSigner(_SensorPeer):
    """Vehicle side: signs each sensor frame for the epoch it last announced."""

    def __init__(self, contract: Contract, key: bytes) -> None:
        super().__init__(contract, key)
        self._epoch: dict[str, int | None] = dict.fromkeys(SENSORS)
        self._counter = dict.fromkeys(SENSORS, 0)

    def sign(self, name: str, values: Mapping[str, float | str], alive: int, epoch: int | None,
             *, strict: bool = True) -> bytes:
        """The sensor frame, E2E-protected and, with an epoch, authenticated for it."""
        if epoch is None:
            return self.contract.encode(name, values, alive, strict=strict)
        f = self.fields[name]
        if self._epoch[name] != epoch:
            self._epoch[name], self._counter[name] = epoch, 0
        counter = self._counter[name]
        if counter >= 1 << COUNTER_BITS:
            raise SecOCError(f"{name}: the freshness counter overflowed within one epoch")
        full = dict(values)
        full[f.epoch_bit] = epoch & 1
        full[f.counter_low] = counter & ((1 << SENSOR_FV_LOW_BITS) - 1)
        full[f.mac] = 0
        plain = self.contract.encode(name, full, alive, strict=strict)
        full[f.mac] = frame_mac(self._cmac, f.frame_id, f.zeroed(plain), freshness(epoch, counter), f.mac_bits)
        self._counter[name] = counter + 1
        return self.contract.encode(name, full, alive, strict=strict)


@dataclass
class _SensorLast:
    epoch: int
    counter: int
    alive: int


class SensorVerifier(_SensorPeer):
    """Controller side: verifies sensor frames against the epochs of authentic syncs.

    ``adopt`` each epoch the command signer took; a frame verifies for the current epoch or the
    one before (its low bit says which) and a counter 1 to ``SENSOR_MAX_ADVANCE`` past the last
    accepted one.  Each failure is counted per message in ``failed``.
    """

    def __init__(self, contract: Contract, key: bytes) -> None:
        super().__init__(contract, key)
        self.current: int | None = None
        self.previous: int | None = None
        self._last: dict[int, _SensorLast | None] = dict.fromkeys(self.by_id)
        self.failed = dict.fromkeys(SENSORS, 0)

    def adopt(self, epoch: int) -> None:
        if self.current is None or epoch > self.current:
            self.previous, self.current = self.current, epoch

    def verify(self, frame_id: int, data: bytes, signals: Mapping[str, float]) -> bool:
        """True if the frame's MAC verifies for a freshness value newer than the last accepted
        one of its message.  ``data`` and ``signals`` must come from a frame that passed
        ``Contract.decode`` (length, CRC, range)."""
        f = self.by_id[frame_id]
        alive, low = int(signals[f.alive]), int(signals[f.counter_low])
        epoch = epoch_named(int(signals[f.epoch_bit]), self.current, self.previous)
        last = self._last[frame_id]
        if epoch is None or (last is not None and epoch < last.epoch):
            self.failed[f.name] += 1
            return False
        if last is not None and epoch == last.epoch:
            advance = counter_advance(alive - last.alive, low - last.counter)
            counter = last.counter + advance
        else:
            advance, counter = 1, low  # the epoch's first accepted frame must be one of its first 8
        # The window first: a replay (or too many lost frames) is refused before any MAC is computed.
        if (advance > SENSOR_MAX_ADVANCE or counter >= 1 << COUNTER_BITS
                or frame_mac(self._cmac, frame_id, f.zeroed(data), freshness(epoch, counter), f.mac_bits)
                != int(signals[f.mac])):
            self.failed[f.name] += 1
            return False
        if last is None:
            self._last[frame_id] = _SensorLast(epoch, counter, alive)
        else:
            last.epoch, last.counter, last.alive = epoch, counter, alive
        return True
