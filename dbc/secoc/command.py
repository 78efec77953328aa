"""Authentication of ``MRS_AuxSteerCmd`` (the controller signs, the actuator verifies) and the
actuator's freshness sync ``MRS_SecOCSync``.

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
MAC is the leading bits of the 128-bit CMAC.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from mrsteer_dbc.contract import Contract, ContractError
from mrsteer_dbc.names import MSG_CMD, MSG_SYNC
from mrsteer_dbc.secoc.cmac import COUNTER_BITS, TruncatedCmac, epoch_named, frame_mac, freshness
from mrsteer_dbc.secoc.frames import AuthFields, sign_frame
from mrsteer_dbc.secoc.keys import SecOCError

COMMAND = MSG_CMD
SYNC = MSG_SYNC
EPOCH_ORIGIN_S = 1767225600  # 2026-01-01T00:00:00Z: the epochs are milliseconds after it


@dataclass(frozen=True)
class Layout:
    """The SecOC fields of the command and the sync, as the DBC defines them."""

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

        def sig(msg: Any, suffix: str) -> tuple[str, int]:
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


class _Peer:
    """What signer and verifier share: the layout, the key, the two MACs."""

    def __init__(self, contract: Contract, key: bytes) -> None:
        try:
            self.layout = Layout.of(contract)
            self.fields = {COMMAND: AuthFields.of(contract, COMMAND)}
        except ContractError as exc:
            raise SecOCError(str(exc)) from None
        self.contract = contract
        self.cmac = TruncatedCmac(key)
        self._cmd = self.fields[COMMAND]
        self._sync = contract.message(SYNC)

    def sync_mac(self, epoch: int) -> int:
        lay = self.layout
        return self.cmac(lay.sync_id.to_bytes(2, "big") + epoch.to_bytes(8, "big"), lay.sync_mac_bits)

    def command_mac(self, zeroed: bytes, fv: int) -> int:
        """MAC of a command payload whose CRC and MAC fields are zero."""
        lay = self.layout
        return frame_mac(self.cmac, lay.cmd_id, zeroed, fv, lay.mac_bits)


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

    def verify(self, frame_id: int, data: bytes, signals: Mapping[str, float]) -> bool:
        """The sync's check in every verifier's shape (``FrameVerifier``): adopt the epoch of an
        authentic sync newer than ours; False (and counted) otherwise."""
        lay = self.layout
        epoch = int(signals[lay.sync_epoch])
        if int(signals[lay.sync_mac]) != self.sync_mac(epoch) or (self.epoch is not None and epoch <= self.epoch):
            self.syncs_rejected += 1
            return False
        self.epoch, self.counter = epoch, 0
        self.syncs_accepted += 1
        return True

    def accept_sync(self, data: bytes) -> bool:
        """``verify`` of a sync payload given alone; ``data`` must have the sync's length."""
        return self.verify(self.layout.sync_id, data, self._sync.decode(data, decode_choices=False, scaling=False))

    def encode(self, name: str, values: Mapping[str, float | str], alive: int, *, strict: bool = True) -> bytes:
        """The command frame, E2E-protected and, once synced, authenticated (otherwise its SecOC
        fields are 0 and the actuator will reject it)."""
        fresh = None
        if self.synced:
            assert self.epoch is not None
            fresh = (self.epoch, self.counter)
            self.counter += 1
        return sign_frame(self.contract, self.cmac, self.fields[name], values, alive, fresh, strict=strict)

    def sign(self, values: Mapping[str, float | str], counter: int) -> bytes:
        """``encode`` of the command."""
        return self.encode(COMMAND, values, counter)


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

    def new_epoch(self) -> dict[str, int]:
        """Start a new epoch: the ``MRS_SecOCSync`` signal values announcing it."""
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
        return {lay.sync_epoch: epoch, lay.sync_mac: self.sync_mac(epoch)}

    def next_sync(self) -> bytes:
        """Start a new epoch and return the ``MRS_SecOCSync`` payload announcing it."""
        return self.contract.encode(SYNC, self.new_epoch())

    def verify(self, frame_id: int, data: bytes, signals: Mapping[str, float]) -> bool:
        """True if the command's MAC verifies for a freshness value newer than the last accepted
        one (which it then becomes).  ``data`` and ``signals`` come from a frame that passed
        ``Contract.decode``."""
        f = self._cmd
        epoch = epoch_named(int(signals[f.epoch_bit]), self.current, self.previous)
        if epoch is None or (self.last is not None and epoch < self.last[0]):
            self.stats.failed += 1
            return False
        first = self.last[1] + 1 if self.last is not None and epoch == self.last[0] else 0
        window = 1 << f.counter_low_bits
        counter = first + ((int(signals[f.counter_low]) - first) % window)
        if counter >= 1 << COUNTER_BITS or self.command_mac(f.zeroed(data), freshness(epoch, counter)) != int(
                signals[f.mac]):
            self.stats.failed += 1
            return False
        self.last = (epoch, counter)
        self.stats.accepted += 1
        return True
