"""Authentication of the sensor frames: the vehicle (the freshness master, which issues the
epochs: ``command.CommandVerifier``) signs them, and the controller verifies them with the
epochs it has taken from authentic syncs.

Classic CAN leaves no room for the command's 16-bit MAC and 4 FV bits: each sensor frame
carries the epoch's low bit and the per-epoch counter's low 3 bits in the spare nibble of byte 1
and an 8-bit MAC in one extra byte.  The receiver recovers the counter from those 3 bits
together with the E2E alive counter (mod 15): 8 and 15 are coprime, so the two residues fix the
counter's advance modulo 120.  The verifier takes an advance of at most ``SENSOR_MAX_ADVANCE``
frames (up to 14 lost, more than the 10 that fault an input by timeout): a replayed frame up to
104 frames old is then refused before its MAC is even checked, and an 8-bit MAC that verifies
by luck (1 in 256) moves the counter on by at most 15 frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from mrsteer_dbc.contract import Contract, ContractError
from mrsteer_dbc.names import SENSORS, VEHICLE_SENSORS
from mrsteer_dbc.secoc.cmac import COUNTER_BITS, TruncatedCmac, epoch_named, frame_mac, freshness
from mrsteer_dbc.secoc.frames import AuthFields, sign_frame
from mrsteer_dbc.secoc.keys import SecOCError

_ALIVE_MODULO = 15  # the E2E alive counter: 0..14
SENSOR_FV_LOW_BITS = 3  # the per-epoch counter's bits on the wire: residues mod 8
_INV8_MOD15 = 2  # 8 * 2 = 16 = 1 (mod 15)
SENSOR_MAX_ADVANCE = 15


class SensorFields(AuthFields):
    """The SecOC fields of one sensor message (a 3-bit FV counter), as the DBC defines them."""

    @classmethod
    def of(cls, contract: Contract, name: str, purpose: str = "sensor SecOC",
           counter_low_bits: int | None = SENSOR_FV_LOW_BITS) -> "SensorFields":
        fields = AuthFields.of(contract, name, purpose, counter_low_bits)
        return cls(**fields.__dict__)


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
            self.fields = {name: SensorFields.of(contract, name) for name in VEHICLE_SENSORS}
        except ContractError as exc:
            raise SecOCError(str(exc)) from None
        self.by_id = {f.frame_id: f for f in self.fields.values()}
        self.contract = contract
        self.cmac = TruncatedCmac(key)


class SensorSigner(_SensorPeer):
    """Vehicle side: signs each sensor frame for the epoch it last announced (``adopt``)."""

    def __init__(self, contract: Contract, key: bytes) -> None:
        super().__init__(contract, key)
        self.epoch: int | None = None  # None: frames go out unsigned
        self._epoch: dict[str, int | None] = dict.fromkeys(VEHICLE_SENSORS)
        self._counter = dict.fromkeys(VEHICLE_SENSORS, 0)

    def adopt(self, epoch: int | None) -> None:
        """Sign from now on for ``epoch`` (each message's counter restarts at its next frame)."""
        self.epoch = epoch

    def encode(self, name: str, values: Mapping[str, float | str], alive: int, *, strict: bool = True) -> bytes:
        """The sensor frame, E2E-protected and, with an epoch, authenticated for it."""
        epoch, fresh = self.epoch, None
        if epoch is not None:
            if self._epoch[name] != epoch:
                self._epoch[name], self._counter[name] = epoch, 0
            counter = self._counter[name]
            if counter >= 1 << COUNTER_BITS:
                raise SecOCError(f"{name}: the freshness counter overflowed within one epoch")
            fresh = (epoch, counter)
            self._counter[name] = counter + 1
        return sign_frame(self.contract, self.cmac, self.fields[name], values, alive, fresh, strict=strict)

    def sign(self, name: str, values: Mapping[str, float | str], alive: int, epoch: int | None,
             *, strict: bool = True) -> bytes:
        """``encode`` for ``epoch`` (adopted first)."""
        self.adopt(epoch)
        return self.encode(name, values, alive, strict=strict)


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
        self.failed = dict.fromkeys(VEHICLE_SENSORS, 0)

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
                or frame_mac(self.cmac, frame_id, f.zeroed(data), freshness(epoch, counter), f.mac_bits)
                != int(signals[f.mac])):
            self.failed[f.name] += 1
            return False
        if last is None:
            self._last[frame_id] = _SensorLast(epoch, counter, alive)
        else:
            last.epoch, last.counter, last.alive = epoch, counter, alive
        return True
