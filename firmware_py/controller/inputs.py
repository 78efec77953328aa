"""Receive state of one sensor input (the C port's per-signal RX record)."""

from __future__ import annotations

import math

import mrsteer_dbc


class Input:
    """Receive state of one sensor message: newest accepted value, its age in cycles, the
    rejections in a row and the cause of the last one."""

    __slots__ = ("name", "signal", "missing_cause", "value", "age", "limit", "rejects", "receiver",
                 "last_counter", "bad_cause")

    def __init__(self, name: str, signal_name: str, missing_cause: int, limit_cycles: int, max_delta: int) -> None:
        self.name = name
        self.signal = signal_name
        self.missing_cause = missing_cause
        self.value = math.nan
        self.age = limit_cycles + 1  # never received: invalid until the first good frame
        self.limit = limit_cycles
        self.rejects = 0
        self.receiver = mrsteer_dbc.E2EReceiver(max_delta)
        self.last_counter = 0
        self.bad_cause = 0
