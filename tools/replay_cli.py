"""``mrsteer replay``: a recorded candump log through the firmware again, offline, and the verdict.

Exit status: 0 when every replayed command and status frame agrees with the recorded ones (for
each implementation asked for), 1 when any disagrees, 2 for an error (one line on stderr), 130
when interrupted (nothing written).
With ``--calibration`` the what-if of the new calibration is reported beside the verdict; the
exit status still says whether the log agrees with the calibration it was recorded with.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

from firmware_py import model_regulator as mr
from firmware_py.controller.node import DEFAULT_RATE_HZ, TRIGGERS
from firmware_py.controller.options import RATES_HELP, calibration_for_rate
from firmware_py.platform.cli import CommandError, add_secoc_args, check_output_dir, secoc_key, warn
from mrsteer_cli.cli_args import count, number

IMPLS = ("python", "c", "both")


def add_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "replay", help="replay a recorded candump log through the firmware and compare the commands",
        description="Feed the sensor frames of a candump -L log (hil run's traffic.log, or candump -L from a car) "
        "through the controller offline - receive checks, freshness, the trigger, step(), cause bits - and "
        "compare every replayed command and status frame with the recorded one. Exit 0 only when they agree.")
    p.add_argument("log", type=Path, metavar="LOG", help="candump -L log file")
    p.add_argument("--calibration", type=Path, metavar="FILE",
                   help="what-if: also replay with this calibration (a key = value calibration file, as "
                   "tests/vectors/*.cfg and mrsteer controller --calibration) and "
                   "report its commands against the recorded ones, with a figure in --out")
    p.add_argument("--recorded-calibration", type=Path, metavar="FILE",
                   help="the calibration the log was recorded with (.cfg; default: the shipped one)")
    p.add_argument("--impl", choices=IMPLS, default="python",
                   help="python (default), c (the C port's step() through ports/c/mrs_replay) or both")
    p.add_argument("--rate-hz", type=number("rate", 1.0, 10000.0), metavar="HZ",
                   help="the recorded controller's rate (default: the summary.json of the hil run beside LOG, else "
                   f"--recorded-calibration's, else {DEFAULT_RATE_HZ:g}); a rate with a calibration of its own "
                   f"({RATES_HELP}) or the calibration files' rate")
    p.add_argument("--trigger", choices=("auto", *TRIGGERS), default="auto",
                   help="the recorded controller's trigger: sensors (lockstep runs) or clock (realtime); auto "
                   "(default): the mode in the summary.json of the hil run beside LOG, else sensors")
    p.add_argument("--timeout-cycles", type=count, default=10, metavar="N",
                   help="the recorded controller's --timeout-cycles (default 10)")
    add_secoc_args(p)
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="write replay.json, replay.csv and, with --calibration, whatif.png here")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.set_defaults(handler=run)


_BadInput = CommandError  # bad input: one line on stderr, exit status 2


def _load(path: Path | None, flag: str) -> mr.ControllerConfig | None:
    from firmware_py import calibration_file

    if path is None:
        return None
    try:
        return calibration_file.load(path)
    except OSError as exc:
        raise _BadInput(f"{flag} {path}: {exc.strerror or exc}") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise _BadInput(f"{flag} {path}: not a usable calibration ({exc})") from None


def _calibration(path: Path | None, flag: str, rate_hz: float, rate_from: str) -> mr.ControllerConfig:
    """The calibration ``flag`` gives (default: the one of the rate), at the log's rate: one made
    for that rate (``calibration_for_rate``, refused in every command's words)."""
    cfg = calibration_for_rate(rate_hz, _load(path, flag), flag=rate_from, file_flag=flag)
    try:
        mr.configure(cfg)
    except ValueError as exc:
        raise _BadInput(f"{flag} {path}: not a usable calibration ({exc})") from None
    return cfg


def _recorded_run(args: argparse.Namespace) -> tuple[str, float, str]:
    """The recorded controller's trigger and rate: as given, else from the hil run's summary.json
    beside the log, else the recorded calibration's, else the defaults; and where they came from."""
    from sim_plant.harness.hil_report import recorded_controller

    found_trigger, found_rate = recorded_controller(args.log)
    trigger = args.trigger if args.trigger != "auto" else (found_trigger or "sensors")
    recorded = _load(args.recorded_calibration, "--recorded-calibration")
    own = 1.0 / recorded.ts if recorded is not None else DEFAULT_RATE_HZ
    rate_hz = args.rate_hz if args.rate_hz is not None else (found_rate or own)
    used = [what for what, given, found in (("trigger", args.trigger != "auto", found_trigger),
                                              ("rate", args.rate_hz is not None, found_rate)) if not given and found]
    if used:
        source = f"{' and '.join(used)} from {args.log.parent / 'summary.json'}"
    elif args.trigger == "auto" or args.rate_hz is None:
        source = "no readable summary.json beside the log: defaults where not given"
    else:
        source = "as given"
    return trigger, rate_hz, source


def run(args: argparse.Namespace) -> int:
    """``mrsteer replay``; an error (bad input, a C port that cannot be had) raises, for
    ``mrsteer_cli.cli.main`` to report in one line."""
    from sim_plant.harness import replay as rp
    from sim_plant.harness import replay_report as report

    check_output_dir("--out", args.out)
    key = secoc_key(args)  # SecOCError, a ValueError: one line
    trigger, rate_hz, source = _recorded_run(args)
    rate_from = "--rate-hz" if args.rate_hz is not None else (
        f"the rate in {args.log.parent / 'summary.json'}" if "rate" in source.split(" from ")[0] else "the rate")
    recorded = _calibration(args.recorded_calibration, "--recorded-calibration", rate_hz, rate_from)
    settings = rp.ReplaySettings(rate_hz=rate_hz, trigger=trigger, timeout_cycles=args.timeout_cycles,
                                 controller=recorded, secoc_key=key)
    new = _calibration(args.calibration, "--calibration", rate_hz, rate_from) if args.calibration else None
    result = rp.replay(args.log, settings, warn=lambda m: warn(getattr(args, "prog", "mrsteer replay"), m))  # LogError, a ValueError: one line
    summaries = []
    if args.impl in ("python", "both"):
        summaries.append(report.summary(result, "python"))
    if args.impl in ("c", "both"):
        from sim_plant.harness import replay_c

        try:
            summaries.append(report.summary(replay_c.replay_c(result), "c"))
        except replay_c.PortError as exc:
            raise _BadInput(str(exc)) from None
    what = None
    if new is not None:  # on the frames as the recorded commands grouped them
        what = report.whatif(rp.replay(args.log, replace(settings, controller=new), like=result,
                                       warn=lambda m: None))
    doc: dict[str, Any] = {"replays": summaries, "recorded_run": source}
    if what is not None:
        doc["whatif"] = {"calibration": str(args.calibration), **report.whatif_summary(what)}
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print(f"recorded controller: {trigger} trigger, {rate_hz:g} Hz ({source})")
        for s in summaries:
            print("\n".join(report.text(s)))
        if what is not None:
            print("\n".join(report.whatif_text(doc["whatif"], str(args.calibration))))
    if args.out is not None:
        _write(args.out, doc, result, what)
    return 0 if all(s["agrees"] for s in summaries) else 1


def _write(out: Path, doc: dict[str, Any], result: Any, what: Any) -> None:
    from firmware_py.platform.files import write_files
    from sim_plant.harness import replay_report as report

    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, str | bytes] = {
        "replay.json": json.dumps(doc, indent=2) + "\n",
        "replay.csv": report.steps_csv(result.steps, what.result.steps if what is not None else None)}
    if what is not None:
        png = report.whatif_png(what, f"what-if: {doc['whatif']['calibration']} on {result.log.name}")
        if png is not None:
            files["whatif.png"] = png
    write_files(out, files)
