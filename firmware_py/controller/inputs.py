"""Receive state of one sensor input (the C port's per-signal RX record; the counter-sequence
state is the link's, ``mrsteer_dbc.link.RxLink``)."""

from __future__ import annotations

import math


class Input:
    """Receive state of one sensor message: newest accepted value, its age in cycles, the
    rejections in a row and the cause of the last one."""

    __slots__ = ("name", "signal", "missing_cause", "value", "age", "limit", "rejects", "last_counter", "bad_cause")

    def __init__(self, name: str, signal_name: str, missing_cause: int, limit_cycles: int) -> None:
        self.name = name
        self.signal = signal_name
        self.missing_cause = missing_cause
        self.value = math.nan
        self.age = limit_cycles + 1  # never received: invalid until the first good frame
        self.limit = limit_cycles
        self.rejects = 0
        self.last_counter = 0
        self.bad_cause = 0
