"""What the controller loop counts and measures, reported by ``--stats-out``."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from firmware_py.controller.timing import LatenessHistogram


@dataclass
class LoopStats:
    cycles: int = 0
    overruns: int = 0
    missed_cycles: int = 0
    rx_frames: int = 0
    rx_rejected: int = 0
    rx_ignored: int = 0
    syncs_rejected: int = 0  # MRS_SecOCSync frames that failed their MAC or were not newer
    rx_auth_failed: int = 0  # sensor frames that failed SecOC (also counted in rx_rejected)
    # sensor frames before the first authentic sync: no epoch to verify them against yet (also
    # counted in rx_rejected, not in rx_auth_failed: not verifiable is not failed)
    rx_unsynced: int = 0
    tx_frames: int = 0
    cmd_withheld: int = 0  # commands not sent: keyed, and no authentic sync adopted yet
    faults_entered: int = 0
    lateness: LatenessHistogram = field(default_factory=LatenessHistogram)
    rss_kb_loop_start: int = 0
    rss_kb_loop_end: int = 0
    platform: dict[str, Any] = field(default_factory=dict)  # what real-time features were applied

    def summary(self) -> dict[str, Any]:
        lat = self.lateness
        return {
            "cycles": self.cycles, "overruns": self.overruns, "missed_cycles": self.missed_cycles,
            "rx_frames": self.rx_frames, "rx_rejected": self.rx_rejected, "rx_ignored": self.rx_ignored,
            "syncs_rejected": self.syncs_rejected, "rx_auth_failed": self.rx_auth_failed,
            "rx_unsynced": self.rx_unsynced,
            "tx_frames": self.tx_frames, "cmd_withheld": self.cmd_withheld, "faults_entered": self.faults_entered,
            "lateness_p50_s": lat.percentile(0.5), "lateness_p99_s": lat.percentile(0.99), "lateness_max_s": lat.max,
            "rss_kb_loop_start": self.rss_kb_loop_start, "rss_kb_loop_end": self.rss_kb_loop_end,
            "rss_kb_growth": self.rss_kb_loop_end - self.rss_kb_loop_start, **self.platform,
        }
