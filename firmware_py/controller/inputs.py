"""Receive state of one sensor input (the C port's per-message RX record; the counter-sequence
state is the link's, ``mrsteer_dbc.link.RxLink``)."""

from __future__ import annotations

import math


class Input:
    """Receive state of one sensor message: newest accepted value (and, for a message that
    carries more measurements, ``extra_signals``' values in ``extra``: the yaw-rate sensor's
    second element; ``MRS_RedundantSensors``' second steering channel and second speed), its age
    in cycles, the rejections in a row and the cause of the last one, and whether a frame of it
    was ever accepted (``seen``: the node's start state waits for every input's first)."""

    __slots__ = ("name", "signal", "extra_signals", "missing_cause", "value", "extra", "age", "limit", "rejects",
                 "last_counter", "bad_cause", "seen")

    def __init__(self, name: str, signal_name: str, missing_cause: int, limit_cycles: int,
                 extra_signals: tuple[str, ...] = ()) -> None:
        self.name = name
        self.signal = signal_name
        self.extra_signals = extra_signals
        self.missing_cause = missing_cause
        self.value = math.nan
        self.extra = [math.nan] * len(extra_signals)  # preallocated, as the C record's array
        self.age = limit_cycles + 1  # never received: invalid until the first good frame
        self.limit = limit_cycles
        self.rejects = 0
        self.last_counter = 0
        self.bad_cause = 0
        self.seen = False

    def valid(self, e2e_fail_max: int) -> bool:
        """Fresh (its last accepted frame within ``limit`` cycles) and not rejected
        ``e2e_fail_max`` times in a row."""
        return self.age <= self.limit and self.rejects < e2e_fail_max
