"""E2E protection as AUTOSAR E2E profile 1, variant 1A: the CRC, the alive counter on the
sender's side and the counter-sequence check on the receiver's (which differs from
E2E_P01Check where docs/can-runtime.md says so).

* the profile-1 CRC as AUTOSAR R4 computes it (E2E_P01Protect, E2E_P01_DATAID_BOTH) in the
  message's ``*_CRC`` signal: ``Crc_CalculateCRC8`` (CRC-8/SAE-J1850, poly 0x1D) chained with
  start value 0xFF and IsFirstCall = FALSE over the data ID's low byte, its high byte, then
  every payload byte except the CRC byte, and the result XORed with 0xFF.  The chaining
  cancels the library's init and output XORs, so this is the bare polynomial with register
  start 0x00 and no final XOR (``Contract.e2e_crc``).  Example: MRS_YawRate (data ID 4353 =
  0x1101) with bytes 1..7 all zero is ``A3 00 00 00 00 00 00 00`` (a single CRC-8/SAE-J1850
  pass with init and final XOR 0xFF, what mrsteer used before, gives 0xDF instead);
* a 4-bit alive counter 0..14 in the ``*_Counter`` signal, incremented per frame sent.

Which messages are protected, their data IDs and where the CRC and counter sit come from the
DBC (``mrsteer_dbc.contract``); nothing here knows a message.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from crccheck.crc import Crc8SaeJ1850

COUNTER_MODULO = 15  # profile 1: counter values 0..14; 15 is never sent


class _Crc8Table(Crc8SaeJ1850):
    """The same CRC without init value and output XOR: its value of one byte is a table entry."""

    _initvalue = 0x00
    _xor_output = 0x00


# crccheck computes bit by bit (about 1 us per byte); the receive path checks a CRC on every
# frame, so the byte-wise table of the same polynomial is taken from crccheck once.
_CRC8_TABLE = bytes(_Crc8Table.calc(bytes((i,))) for i in range(256))


def crc8_sae_j1850(data: bytes, start_value: int = 0xFF, first_call: bool = True) -> int:
    """AUTOSAR ``Crc_CalculateCRC8`` (CRC-8/SAE-J1850), table-driven.

    With ``first_call`` (the default) ``start_value`` is ignored and this is the plain
    CRC-8/SAE-J1850 (init 0xFF, final XOR 0xFF; ``crccheck.crc.Crc8SaeJ1850.calc``).  Otherwise
    ``start_value`` is the previous call's result: the register resumes at ``start_value ^ 0xFF``,
    so chained calls equal one call over the concatenated data.
    """
    crc = 0xFF if first_call else start_value ^ 0xFF
    table = _CRC8_TABLE
    for b in data:
        crc = table[crc ^ b]
    return crc ^ 0xFF


@dataclass(frozen=True)
class E2EConfig:
    data_id: int
    crc_signal: str
    counter_signal: str
    crc_byte: int


class E2EStatus(enum.Enum):
    OK = "ok"
    OK_SOME_LOST = "ok_some_lost"  # counter jumped by 2..max_delta: frames lost, data valid
    INITIAL = "initial"  # first frame seen: accepted, no sequence to compare with
    REPEATED = "repeated"  # same counter again: stale or replayed
    WRONG_SEQUENCE = "wrong_sequence"  # counter jumped too far
    BAD_CRC = "bad_crc"
    BAD_COUNTER = "bad_counter"  # 15, which profile 1 never sends
    BAD_LENGTH = "bad_length"
    OUT_OF_RANGE = "out_of_range"  # a signal outside the DBC's [min, max] or not finite

    @property
    def accepted(self) -> bool:
        return self in (E2EStatus.OK, E2EStatus.OK_SOME_LOST, E2EStatus.INITIAL)


class E2EReceiver:
    """Counter-sequence check of one E2E-protected message (profile 1 style)."""

    def __init__(self, max_delta: int = 3) -> None:
        if not 1 <= max_delta < COUNTER_MODULO:
            raise ValueError("max_delta must be in 1..14")
        self.max_delta = max_delta
        self.last: int | None = None

    def check(self, counter: int) -> E2EStatus:
        if self.last is None:
            self.last = counter
            return E2EStatus.INITIAL
        delta = (counter - self.last) % COUNTER_MODULO
        if delta == 0:
            return E2EStatus.REPEATED
        # Accept and re-synchronise on the new value either way, so one bad jump costs one frame.
        self.last = counter
        if delta == 1:
            return E2EStatus.OK
        if delta <= self.max_delta:
            return E2EStatus.OK_SOME_LOST
        return E2EStatus.WRONG_SEQUENCE

    def reset(self) -> None:
        self.last = None


class AliveCounter:
    """Sender side: 0, 1, ..., 14, 0, ..."""

    def __init__(self) -> None:
        self.value = COUNTER_MODULO - 1

    def next(self) -> int:
        self.value = (self.value + 1) % COUNTER_MODULO
        return self.value
