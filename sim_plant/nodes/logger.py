"""Bus logger: every frame on the bus to a candump ``-L`` log (``(time) iface ID#DATA``, written by
``candump_log``).

Runs until SIGINT/SIGTERM, then drains what is still queued, flushes and reports its count.
``cantools decode dbc/mrsteer.dbc < LOG`` decodes the result.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Sequence, TextIO

import can

from firmware_py.platform.bus_open import BusOpenError, open_bus
from firmware_py.platform.cli import Parser, check_output_file, fail
from firmware_py.platform.lifecycle import run_node
from firmware_py.platform.rx_queue import deepen
from sim_plant.nodes.candump_log import format_line


class Logger:
    def __init__(self, bus: can.BusABC, out: TextIO, iface: str) -> None:
        self.bus, self.out, self.iface = bus, out, iface
        self.frames = 0
        self._running = True

    def stop(self, *_: Any) -> None:
        self._running = False

    def run(self) -> None:
        while self._running:
            msg = self.bus.recv(0.1)
            if msg is not None:
                self._write(msg)
        while (msg := self.bus.recv(0.05)) is not None:  # what was already on its way to us
            self._write(msg)
        self.out.flush()

    def _write(self, msg: can.Message) -> None:
        self.out.write(format_line(msg, self.iface))
        self.frames += 1


def main(argv: Sequence[str] | None = None, prog: str = "python -m sim_plant.nodes.logger") -> int:
    p = Parser(prog=prog, description="Log every CAN frame to a candump -L file until SIGINT/SIGTERM.")
    p.add_argument("--interface")
    p.add_argument("--channel")
    p.add_argument("--out", type=Path, required=True, help="log file to write")
    p.add_argument("--iface-name", default=None, help="interface name written in the log (default: the channel)")
    p.add_argument("--stats-out", type=Path, help="write the frame count as JSON here on exit")
    args = p.parse_args(argv)
    check_output_file(p, "--stats-out", args.stats_out)
    try:
        bus = open_bus(args.interface, args.channel, notice=lambda m: None)
    except BusOpenError as exc:
        return fail(prog, str(exc))
    try:
        out = args.out.open("w")  # a live log, written as frames come: it cannot be atomic
    except OSError as exc:
        bus.shutdown()
        return fail(prog, f"cannot write {args.out}: {exc.strerror or exc}")
    with out:
        queue = deepen(bus)
        log = Logger(bus, out, args.iface_name or args.channel or "can0")

        def run() -> None:
            print("ready", flush=True)  # on stdout, for the supervisor; the signal handlers are set
            log.run()

        return run_node(prog, bus, run, log.stop, [(args.stats_out, lambda: json.dumps({"frames": log.frames,
                                                                                 "rx_queue_bytes": queue}))])


if __name__ == "__main__":
    sys.exit(main())
