"""``mrsteer campaign``: run a validation campaign, report on it, export one sample (docs/campaigns.md)."""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path
from typing import Any

from firmware_py.platform.cli import EXIT_INTERRUPTED, Parser, check_output_dir, check_output_file, fail
from mrsteer_cli.cli_args import int_in, say


def add_parsers(sub: Any) -> None:
    """``mrsteer campaign run|report|export``."""
    camp = sub.add_parser("campaign", help="validation campaigns: thousands of randomised scenarios in batches",
                          description="Validation campaigns on the realistic car (docs/campaigns.md).")
    csub = camp.add_subparsers(dest="campaign_command", required=True, parser_class=Parser)
    p = csub.add_parser("run", help="run a campaign file; results per chunk as Parquet (resumable)",
                        description="Sample the campaign file's scenarios, run each calibration over them with the "
                        "batch engine on every core (or a Dask cluster), and write one Parquet file per chunk to "
                        "--out. Running again on the same --out resumes where an interrupted run stopped.")
    p.add_argument("campaign", type=Path, metavar="CAMPAIGN.toml", help="the campaign file")
    p.add_argument("--out", type=Path, metavar="DIR", help="results directory (default out/campaign-<name>)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="a dask.distributed scheduler, e.g. tcp://host:8786 "
                   "(default: a local cluster)")
    p.add_argument("--workers", type=int_in("workers", 0, 1024), metavar="N",
                   help="local worker processes (default: one per core; 0: in this process, no Dask)")
    p.add_argument("--resume", action="store_true", help="require --out to hold this campaign already (resuming is "
                   "automatic when it does)")
    p.set_defaults(handler=_cmd_run)
    p = csub.add_parser("report", help="pass rates, mu x v maps, histograms, worst cases: PNG and HTML",
                        description="Read a campaign's results and write DIR/report/ (index.html and PNG figures); "
                        "print the pass rates.")
    p.add_argument("dir", type=Path, metavar="DIR", help="the campaign's results directory")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(handler=_cmd_report)
    p = csub.add_parser("export", help="write sample N as a scenario file for `mrsteer hil run --scenario`",
                        description="Write the N-th sample of a campaign as a scenario TOML that `mrsteer hil run "
                        "--scenario FILE` plays on the bus, and beside it (FILE with .cfg) the calibration to replay "
                        "it with (`--calibration FILE.cfg`); the campaign's figures are in the file's comments.")
    p.add_argument("dir", type=Path, metavar="DIR", help="the campaign's results directory")
    p.add_argument("index", type=int_in("sample index", 0, 10**8), metavar="N", help="the sample's index")
    p.add_argument("--out", type=Path, required=True, metavar="FILE.toml", help="the scenario file to write")
    p.add_argument("--calibration", metavar="NAME", help="which of the campaign's calibrations to write beside it "
                   "(default: its first)")
    p.set_defaults(handler=_cmd_export, parser=p)


class Progress:
    """A progress line on stderr: samples done, rate and ETA, redrawn in place."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty()
        self.last = 0.0
        self.start: int | None = None  # runs already done when this run began (resuming)

    def __call__(self, done: int, total: int, seconds: float) -> None:
        now = time.monotonic()
        if done < total and now - self.last < 0.5 and self.tty:
            return
        self.last = now
        if self.start is None:
            self.start = done
        rate = (done - self.start) / seconds if seconds > 0 else 0.0
        width = 30
        bar = "#" * int(width * done / max(total, 1))
        line = f"campaign [{bar:<{width}}] {done}/{total} runs  {rate:,.0f} runs/s  elapsed {seconds:.0f} s"
        if rate > 0 and done < total:  # (no ETA until a chunk of this run has finished)
            line += f"  ETA {(total - done) / rate:.0f} s"
        print(("\r" if self.tty else "") + line, end="" if self.tty and done < total else "\n",
              file=sys.stderr, flush=True)


def _cmd_run(args: argparse.Namespace) -> int:
    from sim_plant.campaign import c_cycle, runner, spec

    try:  # the engine steps the C cycle, compiled at install: without it, one line (not a worker's traceback)
        c_cycle.require()
    except c_cycle.NotBuilt as exc:
        return fail(getattr(args, "prog", "mrsteer campaign run"), str(exc))
    c = spec.load(args.campaign)
    out = args.out or Path("out") / f"campaign-{c.name}"
    check_output_dir("--out", out)
    say(f"campaign {c.name}: {c.samples} samples x {len(c.calibrations)} calibrations "
        f"({', '.join(c.calibrations)}), {c.duration:g} s each, {c.chunks} chunks -> {out}/")
    def interrupted(*_: object) -> None:
        raise KeyboardInterrupt

    # Ctrl-C or a SIGTERM (a batch system's stop) leaves the chunks written so far; even where the
    # shell started us with SIGINT ignored.
    signal.signal(signal.SIGINT, interrupted)
    signal.signal(signal.SIGTERM, interrupted)
    try:
        res = runner.run(c, args.campaign.parent, out, args.scheduler, args.workers, args.resume, Progress())
    except KeyboardInterrupt:
        from sim_plant.campaign.results import done_chunks

        if sys.stderr.isatty():
            print(file=sys.stderr)  # end the progress bar's line
        return fail(getattr(args, "prog", "mrsteer campaign run"),
                    f"interrupted with {len(done_chunks(out))} of {c.chunks} chunks written to {out}/, each complete; "
                    "run the same command again to resume", EXIT_INTERRUPTED)
    runs = res.samples * len(c.calibrations)
    print(f"ran {res.ran} of {res.chunks} chunks ({res.chunks - res.ran} already done) in {res.seconds:.1f} s"
          + (f" on {res.workers} workers" if res.ran else "") + f"; {runs} runs in {out}/")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from sim_plant.campaign import report

    s = report.build(args.dir)
    if args.json:
        print(report.as_json(s))
        return 0
    print(f"campaign {s['campaign']}: {s['samples']} samples; report in {args.dir / 'report' / 'index.html'}")
    for name, c in s["calibrations"].items():
        per = "  ".join(f"{k} {v:.4f}" for k, v in c["per_criterion"].items() if v is not None)
        worst = c["worst"][0] if c["worst"] else None
        print(f"  {name:<12} pass {c['pass_rate']:.4f}   spun {c['spun']} ({c['spun_share']:.1%})   {per}"
              + (f"   worst: sample {worst['index']} ({worst['disturbance']}), "
                 f"peak yaw rate {worst['peak_yaw_rate']:.4g} rad/s" + (" (spun)" if worst["spun"] else "")
                 if worst else ""))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    import numpy as np

    from firmware_py import calibration_file
    from firmware_py.platform.files import write_files
    from sim_plant.campaign import export, params, results, sampling, spec
    from sim_plant.campaign.runner import SPEC_FILE

    check_output_file(args.parser, "--out", args.out)
    spec_path = args.dir / SPEC_FILE
    if not spec_path.is_file():
        raise ValueError(f"{args.dir}: no {SPEC_FILE}: not a campaign's results directory")
    c = spec.parse(spec_path.read_text(), str(spec_path))
    if args.index >= c.samples:
        raise ValueError(f"sample index {args.index} out of range: the campaign has {c.samples} samples")
    name = args.calibration or c.calibrations[0]
    if name not in c.calibrations:
        raise ValueError(f"--calibration {name!r} is not one of the campaign's ({', '.join(c.calibrations)})")
    config = results.calibrations(c, args.dir)[name]
    sc = params.scenario_for(sampling.samples(c, np.array([args.index])).row(0), c.duration)
    cfg_name = args.out.with_suffix(".cfg").name
    replay = (f"mrsteer hil run --scenario {args.out} " +
              ("--controller none" if config is None else f"--calibration {args.out.with_suffix('.cfg')}"))
    notes = [f"campaign {c.name} ({spec_path}), sample {args.index}, calibration {name}", f"replay: {replay}"]
    try:
        table = results.read_all(args.dir).to_pydict()
        for j, i in enumerate(table["index"]):
            if i == args.index:
                figs = ", ".join(f"{k} {table[k][j]:.6g}" for k in ("peak_yaw_rate", "peak_side_slip",
                                                                    "time_at_limit", "fault_steps"))
                notes.append(f"{table['calibration'][j]}: {figs}, pass {table['pass'][j]}")
    except FileNotFoundError:
        pass
    files = {args.out.name: export.to_toml(sc, notes)}
    if config is not None:
        files[cfg_name] = f"# campaign {c.name}: calibration {name}\n" + calibration_file.dumps(config)
    write_files(args.out.parent, files)  # both or neither
    print(f"wrote sample {args.index} ({sc.description}) to {args.out}" +
          (f" and calibration {name} to {args.out.with_suffix('.cfg')}" if config is not None else "") +
          f"; replay: {replay}")
    return 0
