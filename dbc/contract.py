"""The DBC loaded once (strict) with each message's E2E configuration: encoding sets the
alive counter and the CRC, decoding checks length, CRC, counter value and every signal's range.

A signal whose value table names a raw value ``SNA`` (signal not available) decodes to NaN at
that value, outside the range check, and encodes NaN (or a left-out value, when SNA is its DBC
start value) as it: a sender without that signal's source says so in the frame.

A signal with the DBC attribute ``MRS_RoundTowardZero`` (the command's angle) encodes to the raw
value nearest to its value that is not further from zero (``toward_zero_raw``); every other
signal to the nearest, as cantools does.

Every frame layout, range, cycle time and E2E data ID comes from ``mrsteer.dbc`` through
cantools; nothing here knows a bit position.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import cantools

from mrsteer_dbc.e2e import COUNTER_MODULO, E2EConfig, E2EStatus, crc8_sae_j1850

DBC_PATH = Path(__file__).with_name("mrsteer.dbc")
SNA = "SNA"  # a value table's label for 'signal not available'


def sna_raw(signal: Any) -> int | None:
    """A cantools signal's raw 'not available' value (its value table's ``SNA``), if it has one:
    the one place that reads the label, for the Python contract and the C glue alike."""
    return next((int(raw) for raw, label in (signal.choices or {}).items() if str(label) == SNA), None)


def rounds_toward_zero(signal: Any) -> bool:
    """The cantools signal has the DBC attribute ``MRS_RoundTowardZero`` = 1: the one place that
    reads it, for the Python contract and the C glue alike."""
    attr = (signal.dbc.attributes if signal.dbc is not None else {}).get("MRS_RoundTowardZero")
    return attr is not None and int(attr.value) == 1


def toward_zero_raw(value: float, scale: float, offset: float) -> int:
    """The raw value nearest to ``value`` (ties to even, as cantools rounds) whose decoded value
    ``raw * scale + offset`` is not further from zero than ``value``: one step back toward zero
    where the nearest one is beyond it (the command at the 3 deg limit, 0.0523599 rad at 1e-6
    rad, goes out as 52359, not 52360)."""
    raw = round((value - offset) / scale)
    decoded = raw * scale + offset
    if value > 0.0 and decoded > value:
        raw -= 1
    elif value < 0.0 and decoded < value:
        raw += 1
    return raw


def _carried(signal: Any) -> tuple[float, float]:
    """The physical range a cantools signal's bits can carry, less its SNA raw value where that
    is at an end (so that a saturated value does not read as 'not available')."""
    bits = signal.length
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signal.is_signed else (0, (1 << bits) - 1)
    sna = sna_raw(signal)
    lo, hi = lo + (sna == lo), hi - (sna == hi)
    a, b = (signal.conversion.raw_to_scaled(raw, decode_choices=False) for raw in (lo, hi))
    return (min(a, b), max(a, b))


class ContractError(ValueError):
    """The DBC does not satisfy what the code requires of it."""


@dataclass
class Decoded:
    name: str
    signals: dict[str, float]
    status: E2EStatus
    counter: int | None


class Contract:
    """The DBC loaded once (strict), with per-message E2E configuration."""

    def __init__(self, path: Path | str = DBC_PATH) -> None:
        try:
            self.db = cantools.database.load_file(str(path), strict=True)
        except FileNotFoundError:
            raise ContractError(f"DBC file not found: {path}") from None
        except OSError as exc:  # a directory, a file that cannot be read: its reason, not its errno
            raise ContractError(f"cannot load DBC {path}: {exc.strerror or exc}") from None
        except Exception as exc:  # cantools raises several parser error types
            raise ContractError(f"cannot load DBC {path}: {exc}") from None
        self.path = Path(path)
        self._by_name = {m.name: m for m in self.db.messages}
        self._by_id = {m.frame_id: m for m in self.db.messages}
        self._e2e = {m.name: self._e2e_config(m) for m in self.db.messages}
        # Signals with a DBC start value (GenSigStartValue) may be left out when encoding: the
        # optional SecOC fields are 0 unless authentication fills them.
        self._defaults = {m.name: {s.name: s.initial for s in m.signals if s.initial is not None}
                          for m in self.db.messages}
        # The physical value cantools decodes an SNA raw value to, per signal that has one.
        self._sna = {m.name: {s.name: s.conversion.raw_to_scaled(raw, decode_choices=False)
                              for s in m.signals if (raw := sna_raw(s)) is not None}
                     for m in self.db.messages}
        self._carried = {m.name: {s.name: _carried(s) for s in m.signals} for m in self.db.messages}
        # (signal, scale, offset) of the signals rounded toward zero (MRS_RoundTowardZero).
        self._toward_zero = {m.name: [(s.name, float(s.scale), float(s.offset)) for s in m.signals
                                      if rounds_toward_zero(s)] for m in self.db.messages}
        for m in self.db.messages:
            for name, scale, _ in self._toward_zero[m.name]:
                if scale <= 0.0 or m.get_signal_by_name(name).is_float:
                    raise ContractError(f"{name}: MRS_RoundTowardZero needs a positive scale and integer raw values")

    @staticmethod
    def _e2e_config(msg: Any) -> E2EConfig | None:
        attrs = msg.dbc.attributes if msg.dbc is not None else {}
        profile = attrs.get("E2E_Profile")
        if profile is None or profile.value in ("", None):
            return None
        if profile.value != "P01A":
            raise ContractError(f"{msg.name}: unsupported E2E profile {profile.value!r}")
        data_id = attrs["E2E_DataID"].value if "E2E_DataID" in attrs else 0
        crc = [s for s in msg.signals if s.name.endswith("_CRC")]
        ctr = [s for s in msg.signals if s.name.endswith("_Counter")]
        if len(crc) != 1 or len(ctr) != 1:
            raise ContractError(f"{msg.name}: E2E needs exactly one *_CRC and one *_Counter signal")
        if crc[0].length != 8 or crc[0].start % 8 != 0 or crc[0].byte_order != "little_endian":
            raise ContractError(f"{msg.name}: the CRC must be one whole byte")
        if ctr[0].length != 4:
            raise ContractError(f"{msg.name}: the alive counter must be 4 bits")
        return E2EConfig(int(data_id), crc[0].name, ctr[0].name, crc[0].start // 8)

    # ------------------------------------------------------------------ lookup

    def message(self, name: str) -> Any:
        return self._by_name[name]

    def frame_id(self, name: str) -> int:
        return self._by_name[name].frame_id

    def name_of(self, frame_id: int) -> str | None:
        msg = self._by_id.get(frame_id)
        return msg.name if msg is not None else None

    def e2e(self, name: str) -> E2EConfig | None:
        return self._e2e[name]

    def cycle_time_s(self, name: str, control_period: float | None = None) -> float | None:
        """The message's cycle in s; a control-loop message runs at ``control_period`` if given."""
        if control_period is not None and self.is_control_loop(name):
            return control_period
        ms = self._by_name[name].cycle_time
        return ms / 1000.0 if ms else None

    def is_control_loop(self, name: str) -> bool:
        """Sent once per control period (DBC attribute MRS_ControlLoop = 1)."""
        msg = self._by_name[name]
        attr = (msg.dbc.attributes if msg.dbc is not None else {}).get("MRS_ControlLoop")
        return attr is not None and int(attr.value) == 1

    def has_sna(self, name: str, signal: str) -> bool:
        """The signal has a raw value meaning 'not available' (decoded as NaN)."""
        return signal in self._sna[name]

    def signal_range(self, name: str, signal: str) -> tuple[float, float]:
        sig = self._by_name[name].get_signal_by_name(signal)
        return float(sig.minimum), float(sig.maximum)

    def signal_scale(self, name: str, signal: str) -> float:
        """The signal's resolution: its DBC scale factor."""
        return float(self._by_name[name].get_signal_by_name(signal).scale)

    # ------------------------------------------------------------------ encode

    def e2e_crc(self, name: str, payload: bytes) -> int:
        """AUTOSAR R4 E2E_P01 CRC, data ID mode BOTH (the only mode the contract selects):
        ``Crc_CalculateCRC8`` chained from start value 0xFF with IsFirstCall = FALSE over
        (data ID low byte, data ID high byte, payload without the CRC byte), then XOR 0xFF."""
        cfg = self._e2e[name]
        assert cfg is not None
        body = payload[:cfg.crc_byte] + payload[cfg.crc_byte + 1:]
        return crc8_sae_j1850(bytes((cfg.data_id & 0xFF, cfg.data_id >> 8)) + body, 0xFF, False) ^ 0xFF

    def encode(self, name: str, values: Mapping[str, float | str], counter: int | None = None,
               *, strict: bool = True) -> bytes:
        """Encode physical values; for E2E messages set the counter and the CRC.

        Signals not given take their DBC start value where it has one.  ``strict=False`` lets a
        test bench send values outside the DBC ranges on purpose, as far as each signal's bits
        carry them (saturated there, short of an SNA raw value, not an encoder's overflow).
        """
        return self.seal(name, self.encode_unsealed(name, values, counter, strict=strict))

    def encode_unsealed(self, name: str, values: Mapping[str, float | str], counter: int | None = None,
                        *, strict: bool = True) -> bytearray:
        """``encode`` with the E2E CRC byte left 0: what a SecOC signer authenticates before it
        ``seal``s the frame."""
        msg = self._by_name[name]
        cfg = self._e2e[name]
        full = {**self._defaults[name], **values}
        for sig in self._sna[name]:
            value = full.get(sig)
            if isinstance(value, float) and math.isnan(value):
                full[sig] = SNA
        if not strict:
            for sig, (lo, hi) in self._carried[name].items():
                value = full.get(sig)
                if isinstance(value, int | float) and not isinstance(value, bool) and not math.isnan(value):
                    full[sig] = min(max(value, lo), hi)
        for sig, scale, offset in self._toward_zero[name]:
            value = full.get(sig)
            if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
                # the decoded value of the raw value chosen: cantools rounds it back to that raw value
                full[sig] = toward_zero_raw(value, scale, offset) * scale + offset
        if cfg is not None:
            if counter is None:
                raise ValueError(f"{name} is E2E-protected: give the alive counter")
            full[cfg.counter_signal] = counter
            full[cfg.crc_signal] = 0
        return bytearray(msg.encode(full, strict=strict, scaling=True))

    def seal(self, name: str, data: bytearray) -> bytes:
        """The frame with its E2E CRC set (last: the CRC covers everything else)."""
        cfg = self._e2e[name]
        if cfg is not None:
            data[cfg.crc_byte] = self.e2e_crc(name, bytes(data))
        return bytes(data)

    # ------------------------------------------------------------------ decode

    def decode(self, frame_id: int, data: bytes) -> Decoded | None:
        """Decode a frame and check its length, CRC and ranges (not its counter sequence:
        that needs receiver state, see ``E2EReceiver``).  None for frames not in the DBC."""
        msg = self._by_id.get(frame_id)
        if msg is None:
            return None
        if len(data) != msg.length:
            return Decoded(msg.name, {}, E2EStatus.BAD_LENGTH, None)
        cfg = self._e2e[msg.name]
        if cfg is not None and data[cfg.crc_byte] != self.e2e_crc(msg.name, data):
            return Decoded(msg.name, {}, E2EStatus.BAD_CRC, None)
        signals = msg.decode(data, decode_choices=False, scaling=True)
        counter = int(signals[cfg.counter_signal]) if cfg is not None else None
        if counter is not None and counter >= COUNTER_MODULO:
            return Decoded(msg.name, signals, E2EStatus.BAD_COUNTER, counter)
        sna = self._sna[msg.name]
        for sig in msg.signals:
            value = signals[sig.name]
            if sig.name in sna and value == sna[sig.name]:
                signals[sig.name] = math.nan
                continue
            if not math.isfinite(value) or (sig.minimum is not None and value < sig.minimum) or (
                    sig.maximum is not None and value > sig.maximum):
                return Decoded(msg.name, signals, E2EStatus.OUT_OF_RANGE, counter)
        return Decoded(msg.name, signals, E2EStatus.OK, counter)


_default: Contract | None = None


def load(path: Path | str | None = None) -> Contract:
    """The contract from ``path``, or the shipped ``mrsteer.dbc`` (loaded once)."""
    global _default
    if path is not None:
        return Contract(path)
    if _default is None:
        _default = Contract()
    return _default
