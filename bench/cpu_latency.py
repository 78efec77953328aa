"""The CPUs' wake-up latency bound (Linux PM QoS, ``/dev/cpu_dma_latency``) held during the loop
bench, as ``cyclictest`` holds it: with 0 us the idle governor keeps to its polling state, so a
deadline that falls while a CPU idles is not delayed by the way out of a deeper idle state (on
a VM, a halt and the hypervisor's reschedule). The bound lasts while the file stays open."""

from __future__ import annotations

import os
import struct
from pathlib import Path
from types import TracebackType
from typing import Any

DEVICE = Path("/dev/cpu_dma_latency")


class CpuLatency:
    """``with CpuLatency(0) as held:`` -- ``held.state`` says what was granted (``{"us": 0}``) or
    why not (``{"denied": ...}``); nothing is raised where the device is missing or closed to us."""

    def __init__(self, us: int = 0, device: Path = DEVICE) -> None:
        if not 0 <= us <= 2_000_000_000:
            raise ValueError(f"latency bound must be in [0, 2e9] us, got {us}")
        self.us, self.device = us, device
        self.fd: int | None = None
        self.state: dict[str, Any] = {}

    def __enter__(self) -> "CpuLatency":
        try:
            self.fd = os.open(self.device, os.O_WRONLY)
            os.write(self.fd, struct.pack("i", self.us))
            self.state = {"us": self.us}
        except OSError as exc:
            self.close()
            self.state = {"denied": f"{self.device}: {exc.strerror or exc}"}
        return self

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()
