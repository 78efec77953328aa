"""The plausibility monitor's clock in the controller node: the yaw-rate sensor's samples,
counted by the frames' alive counter, and the redundant frame's timing against that count.

The monitor (``firmware_py.plausibility``) filters, counts and differentiates in steps of its
``ts``, the yaw-rate sample time.  On the bus a sample can be lost, rejected, late, or come in a
burst with others, and a plant that cannot keep real time sends fewer samples than the loop
runs periods; so the node steps the monitor once per *sample* (``samples``), not per period, and
judges each ``MRS_RedundantSensors`` sample by whether the samples counted since the last one
match what its own alive counter says elapsed (``redundant_in_time``).  The C node keeps the
same counts (``ports/c/mrs_node_core.c``: ``yaw_samples``, ``red_cycles``, ``red_usable``).
"""

from __future__ import annotations

from mrsteer_dbc.e2e import COUNTER_MODULO

# Yaw-rate samples (the monitor's steps) a redundant sample's arrival may differ from its alive
# counter's account of the time (delta x its DBC cycle) before the node withholds it from the monitor.
REDUNDANT_JITTER_CYCLES = 2


class SampleClock:
    """Counts of one node: call ``yaw_frame`` and ``redundant_frame`` for each accepted frame,
    ``tick`` once per cycle after reading ``samples``."""

    __slots__ = ("yaw_limit", "red_expected", "yaw_counter", "yaw_samples", "red_counter", "red_samples",
                 "redundant_in_time")

    def __init__(self, red_expected: float, yaw_limit: int) -> None:
        self.yaw_limit = yaw_limit  # the yaw rate's timeout in cycles: a longer gap is no longer counted
        self.red_expected = red_expected  # yaw-rate samples per redundant sample (the DBC cycles' ratio)
        self.yaw_counter = -1  # alive counter of the newest accepted yaw-rate frame; -1 before the first
        self.yaw_samples = 0  # yaw-rate samples since the last tick, by that counter
        self.red_counter = -1  # alive counter of the newest accepted redundant frame; -1 before the first
        self.red_samples = 0  # yaw-rate samples counted since it arrived
        self.redundant_in_time = False  # the held redundant sample arrived in time

    @property
    def samples(self) -> int:
        """Yaw-rate samples since the last tick (a lost or rejected frame's too), at most ``yaw_limit``."""
        return min(self.yaw_samples, self.yaw_limit)

    def yaw_frame(self, counter: int) -> None:
        self.yaw_samples += 1 if self.yaw_counter < 0 else (counter - self.yaw_counter) % COUNTER_MODULO
        self.yaw_counter = counter

    def redundant_frame(self, counter: int) -> None:
        """A redundant sample is in time when it arrived within ``REDUNDANT_JITTER_CYCLES`` samples
        of what its alive counter says elapsed since the one before (the first one is)."""
        # The yaw-rate samples drained before it in this cycle are not yet in red_samples (the
        # tick adds the cycle's count): they belong to this interval, and not to the next.
        before = self.samples
        if self.red_counter >= 0:
            expected = ((counter - self.red_counter) % COUNTER_MODULO) * self.red_expected
            self.redundant_in_time = abs(self.red_samples + before - expected) <= REDUNDANT_JITTER_CYCLES
        else:
            self.redundant_in_time = True
        self.red_counter = counter
        self.red_samples = -before

    def tick(self) -> None:
        """End of the cycle's reading: the samples counted move to the redundant frame's count."""
        self.red_samples += self.samples
        self.yaw_samples = 0
