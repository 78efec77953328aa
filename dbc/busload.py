"""CAN bus load of the contract: every cyclic frame of the DBC at its cycle time.

Classic CAN, 11-bit identifiers, data frames.  A frame with n data bytes has 47 + 8n bits
from start-of-frame to the end of the interframe space (SOF 1, identifier 11, RTR 1, IDE 1,
r0 1, DLC 4, data 8n, CRC 15, CRC delimiter 1, ACK 2, EOF 7, IFS 3).  Bit stuffing applies to
the 34 + 8n bits from SOF to the end of the CRC; the worst case adds floor((34 + 8n - 1) / 4)
stuff bits (Davis, Burns, Bril, Lukkien: "Controller Area Network (CAN) schedulability
analysis: refuted, revisited and revised", Real-Time Systems 35, 2007, eq. 2).  "Nominal" is
the frame without stuff bits, the lower bound.

Frames of the control loop (DBC attribute ``MRS_ControlLoop`` = 1) are sent once per control
period, so their cycle follows the control rate; the others keep their ``GenMsgCycleTime``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from mrsteer_dbc import Contract

FRAME_OVERHEAD_BITS = 47
STUFFED_OVERHEAD_BITS = 34


def frame_bits(data_bytes: int, worst_case: bool) -> int:
    """Bits on the wire for one standard-ID data frame, including the interframe space."""
    if not 0 <= data_bytes <= 8:
        raise ValueError(f"classic CAN carries 0..8 data bytes, got {data_bytes}")
    bits = FRAME_OVERHEAD_BITS + 8 * data_bytes
    if worst_case:
        bits += (STUFFED_OVERHEAD_BITS + 8 * data_bytes - 1) // 4
    return bits


@dataclass(frozen=True)
class MessageLoad:
    name: str
    frame_id: int
    length: int
    cycle_s: float
    control_loop: bool
    bits_nominal: int
    bits_worst: int
    load_percent_nominal: float
    load_percent_worst: float


@dataclass(frozen=True)
class BusLoad:
    bitrate: float
    rate_hz: float
    messages: list[MessageLoad]

    @property
    def load_percent_nominal(self) -> float:
        return sum(m.load_percent_nominal for m in self.messages)

    @property
    def load_percent_worst(self) -> float:
        return sum(m.load_percent_worst for m in self.messages)

    def as_dict(self) -> dict[str, Any]:
        return {
            "bitrate": self.bitrate, "rate_hz": self.rate_hz,
            "load_percent_nominal": self.load_percent_nominal, "load_percent_worst": self.load_percent_worst,
            "messages": [vars(m) for m in self.messages],
        }


#: The bus the shipped design budgets, bit/s (classic CAN at 500 kbit/s: docs/design.md, `mrsteer design busload`).
BITRATE = 500_000


def bus_load(contract: Contract, bitrate: float, rate_hz: float | None = None) -> BusLoad:
    """Load of every cyclic message; ``rate_hz`` sets the control-loop frames' rate (default:
    the DBC's cycle time of those frames, i.e. the shipped default rate)."""
    if not bitrate > 0.0:
        raise ValueError(f"bitrate must be positive, got {bitrate}")
    if rate_hz is not None and not rate_hz > 0.0:
        raise ValueError(f"control rate must be positive, got {rate_hz}")
    period = None if rate_hz is None else 1.0 / rate_hz
    rows = []
    for msg in contract.db.messages:
        loop = contract.is_control_loop(msg.name)
        cycle = period if (loop and period is not None) else contract.cycle_time_s(msg.name)
        if cycle is None:
            continue  # event-driven only: no steady load
        nom, worst = frame_bits(msg.length, False), frame_bits(msg.length, True)
        rows.append(MessageLoad(msg.name, msg.frame_id, msg.length, cycle, loop, nom, worst,
                                100.0 * nom / cycle / bitrate, 100.0 * worst / cycle / bitrate))
    rows.sort(key=lambda m: m.frame_id)
    default_rate = 1.0 / min((m.cycle_s for m in rows if m.control_loop), default=1.0)
    return BusLoad(bitrate, rate_hz if rate_hz is not None else default_rate, rows)


def max_rate_hz(contract: Contract, bitrate: float, load_percent: float) -> float:
    """Highest control rate whose worst-case load stays at or below ``load_percent``."""
    fixed = bus_load(contract, bitrate, 1.0)
    other = sum(m.load_percent_worst for m in fixed.messages if not m.control_loop)
    per_hz = sum(m.load_percent_worst for m in fixed.messages if m.control_loop)
    if per_hz == 0.0:
        raise ValueError("the DBC marks no control-loop message")
    return max(0.0, (load_percent - other) / per_hz)
