"""Hardware-in-the-loop runner: plant, controller and bus logger as separate processes.

``run()`` starts (on the fallback bus: a private broker first) the logger, the controller and
the plant, waits for the plant to play its scenario, stops the controller (which sends its
final zero command) and the logger, and turns the log into a CSV of decoded signals, a plot
and a JSON summary.  If any process dies early the others are stopped, nothing is left
running, and ``HilError`` names the process and its exit status.  Every child gets SIGTERM if
this process dies (Linux ``PR_SET_PDEATHSIG``), so even a killed runner leaves no orphans.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shutil
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

import mrsteer_dbc
from mrsteer_dbc import secoc as secoc_mod
from firmware_py.platform import bus_open
from firmware_py import model_regulator as mr
from firmware_py.platform.files import write_files
from sim_plant.car import scenario as scn
from sim_plant.offline.closed_loop import discrete_loop_poles
from sim_plant.harness.processes import Proc, RunError, spawn, stop, tail, wait_for_socket, wait_ready, wait_stderr
from sim_plant.car.vehicle import VehicleParams

MODES = ("lockstep", "realtime")
_LINE = re.compile(r"\((?P<t>[0-9.]+)\)\s+(?P<iface>\S+)\s+(?P<id>[0-9A-Fa-f]+)#(?P<data>[0-9A-Fa-f]*)")


HilError = RunError  # a HIL run failed; the message says which process and how


_DEFAULT = mr.ControllerConfig()


@dataclass(frozen=True)
class HilConfig:
    scenario: str = "paper-fig9"
    mode: str = "lockstep"
    rate_hz: float = 1.0 / _DEFAULT.ts
    interface: str | None = None
    channel: str | None = None
    v: float | None = None
    mu: float | None = None
    mz: float | None = None
    controller: str = mr.Q_LIMITED  # or "none"
    k: float = _DEFAULT.k
    tau: float = _DEFAULT.tau
    tau_n: float = _DEFAULT.tau_n
    model_delay: int = _DEFAULT.model_delay_steps
    delay_steps: int = 1
    out: Path = Path("out/hil")
    secoc_key: bytes | None = None  # authenticate the commands and the sensor frames (mrsteer_dbc.secoc)


@dataclass
class HilRun:
    """What ``run()`` produced."""

    summary: dict[str, Any]
    out: Path
    files: list[Path] = field(default_factory=list)


def run(cfg: HilConfig, progress: Callable[[str], None] | None = None) -> HilRun:
    say = progress or (lambda m: None)
    if cfg.mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}")
    sc = scn.load(cfg.scenario).with_overrides(v=cfg.v, mu=cfg.mu, mz=cfg.mz)
    ctrl = mr.ControllerConfig(q_form=cfg.controller if cfg.controller != "none" else mr.Q_LIMITED, k=cfg.k,
                               tau=cfg.tau, tau_n=cfg.tau_n, ts=1.0 / cfg.rate_hz, model_delay_steps=cfg.model_delay)
    mr.configure(ctrl)  # reject an impossible calibration before starting anything
    if cfg.out.exists() and not cfg.out.is_dir():
        raise ValueError(f"--out {cfg.out} exists and is not a directory")
    cfg.out.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".hil-", dir=cfg.out))
    procs: list[Proc] = []
    try:
        iface, channel = bus_open.resolve(cfg.interface, cfg.channel, notice=say)
        bus_args = ["--interface", iface] + (["--channel", channel] if channel else [])
        env = dict(os.environ)
        secoc: list[str] = []
        if cfg.secoc_key is not None:
            # Through the environment, not argv: a command line is visible to every user.
            env[secoc_mod.KEY_ENV] = cfg.secoc_key.hex()
            secoc = ["--secoc"]
        if iface == bus_open.FALLBACK[0] and cfg.channel is None:
            # A private bus for this run: nothing else on it, and it goes away with the run.
            channel = f"hil-{os.getpid()}-{int(time.time() * 1000) % 100000}"
            bus_args = ["--interface", iface, "--channel", channel]
            procs.append(spawn("bus broker", [sys.executable, "-m", "firmware_py.platform.fallback_broker", "--channel", channel],
                                work, env))
            wait_for_socket(channel, procs[-1])
        say(f"bus: {iface} {channel}")

        logger = spawn("logger", [sys.executable, "-m", "sim_plant.nodes.logger", *bus_args, "--out",
                                   str(work / "traffic.log"), "--iface-name", str(channel),
                                   "--stats-out", str(work / "logger.json")], work, env, stdout=True)
        procs.append(logger)
        wait_ready(logger)

        if cfg.controller != "none":
            procs.append(spawn("controller", [
                sys.executable, "-m", "firmware_py", *bus_args, "--rate-hz", repr(cfg.rate_hz),
                "--trigger", "sensors" if cfg.mode == "lockstep" else "clock", "--controller", cfg.controller,
                "--k", repr(cfg.k), "--tau", repr(cfg.tau), "--tau-n", repr(cfg.tau_n),
                "--model-delay", str(cfg.model_delay),
                "--stats-out", str(work / "controller.json"), *secoc], work, env))
            wait_stderr(procs[-1], "running at")  # bus open, filters set: the first frame will count
        plant_cmd = [sys.executable, "-m", "sim_plant", *bus_args, "--scenario", cfg.scenario,
                     "--mode", cfg.mode, "--rate-hz", repr(cfg.rate_hz), "--delay-steps", str(cfg.delay_steps),
                     "--stats-out", str(work / "plant.json"), *secoc]
        for flag, value in (("--v", cfg.v), ("--mu", cfg.mu), ("--mz", cfg.mz)):
            if value is not None:
                plant_cmd += [flag, repr(value)]
        if cfg.controller == "none":
            plant_cmd += ["--no-controller"]
        plant = spawn("plant", plant_cmd, work, env)
        procs.append(plant)
        say(f"running {sc.name}: {sc.duration:g} s, {cfg.mode}, {cfg.rate_hz:g} Hz, controller {cfg.controller}")

        limit = time.monotonic() + max(120.0, 40.0 * sc.duration)
        while plant.popen.poll() is None:
            for p in procs:
                if p is not plant and p.popen.poll() is not None:
                    raise HilError(f"{p.name} exited unexpectedly with status {p.popen.returncode}"
                                   f"{tail(p)} ; stopped the others")
            if time.monotonic() > limit:
                raise HilError("the plant did not finish in time; stopped everything")
            time.sleep(0.05)
        if plant.popen.returncode != 0:
            raise HilError(f"plant exited with status {plant.popen.returncode}{tail(plant)}")
        for p in [p for p in procs if p.name == "controller"] + [logger]:
            stop(p)
            if p.popen.returncode not in (0, -signal.SIGTERM):
                raise HilError(f"{p.name} exited with status {p.popen.returncode}{tail(p)}")
        return _finish(cfg, sc, ctrl, work, say)
    except BaseException:
        partial = work / "traffic.log"
        if partial.exists():
            shutil.copy(partial, cfg.out / "traffic.partial.log")
        raise
    finally:
        for p in reversed(procs):
            stop(p)
        shutil.rmtree(work, ignore_errors=True)


# ------------------------------------------------------------------------- results


@dataclass
class Frame:
    t: float
    frame_id: int
    data: bytes


def read_candump(path: Path) -> list[Frame]:
    frames = []
    for line in path.read_text().splitlines():
        m = _LINE.match(line.strip())
        if m:
            frames.append(Frame(float(m["t"]), int(m["id"], 16), bytes.fromhex(m["data"])))
    return frames


def _finish(cfg: HilConfig, sc: scn.Scenario, ctrl: mr.ControllerConfig, work: Path,
            say: Callable[[str], None]) -> HilRun:
    contract = mrsteer_dbc.load()
    frames = read_candump(work / "traffic.log")
    stats = {name: _load_json(work / f"{name}.json") for name in ("plant", "controller", "logger")}
    rows, summary = summarize(frames, contract, cfg, sc, ctrl)
    summary["frames"] = {
        "on_bus_logged": stats["logger"].get("frames", len(frames)),
        "sent_plant": stats["plant"].get("tx_frames"),
        "sent_controller": stats["controller"].get("tx_frames"),
        "received_controller": stats["controller"].get("rx_frames"),
        "rejected_controller": stats["controller"].get("rx_rejected"),
        "rejected_plant": stats["plant"].get("cmd_rejected"),
        "auth_failed_plant": stats["plant"].get("cmd_auth_failed"),
    }
    summary["secoc"] = cfg.secoc_key is not None
    summary["loop"] = {"controller": stats["controller"], "plant": stats["plant"]}
    files = {
        "traffic.log": (work / "traffic.log").read_bytes(),
        "signals.csv": _signals_csv(rows),
        "summary.json": (json.dumps(summary, indent=2) + "\n").encode(),
    }
    png = _plot(rows, summary)
    if png is not None:
        files["plot.png"] = png
    written = write_files(cfg.out, files)
    say(f"wrote {', '.join(files)} to {cfg.out}/")
    return HilRun(summary, cfg.out, written)


def _load_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def summarize(frames: list[Frame], contract: mrsteer_dbc.Contract, cfg: HilConfig, sc: scn.Scenario,
              ctrl: mr.ControllerConfig) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Decoded rows for the CSV, and the summary with the keys of ``mrsteer sim disturbance``."""
    rows = []
    for f in frames:
        d = contract.decode(f.frame_id, f.data)
        if d is None:
            rows.append({"t_s": f.t, "message": f"0x{f.frame_id:X}", "e2e": "unknown"})
            continue
        rows.append({"t_s": f.t, "message": d.name, "e2e": d.status.value, **d.signals})
    yaw = [r for r in rows if r["message"] == "MRS_YawRate" and "YawRate_YawRate" in r]
    cmds = [r for r in rows if r["message"] == "MRS_AuxSteerCmd" and "AuxSteerCmd_Angle" in r]
    if not yaw:
        raise HilError("no yaw-rate frames on the bus: the plant never published")
    t0, t_end = yaw[0]["t_s"], yaw[-1]["t_s"]
    # Commands that belong to the plant's run: each answers a yaw-rate frame (matched by counter).
    answered, latencies = [], []
    j = 0
    for i, y in enumerate(yaw):
        nxt = yaw[i + 1]["t_s"] if i + 1 < len(yaw) else math.inf
        while j < len(cmds) and cmds[j]["t_s"] < y["t_s"]:
            j += 1
        k = j
        while k < len(cmds) and cmds[k]["t_s"] < nxt + 0.5 / cfg.rate_hz:
            if int(cmds[k]["AuxSteerCmd_MeasCounter"]) == int(y["YawRate_Counter"]):
                answered.append(cmds[k])
                latencies.append(cmds[k]["t_s"] - y["t_s"])
                break
            k += 1
    in_run = [c for c in cmds if t0 <= c["t_s"] <= t_end + 1.0 / cfg.rate_hz]
    aux = np.array([c["AuxSteerCmd_Angle"] for c in (answered if cfg.mode == "lockstep" else in_run)] or [0.0])
    r = np.array([y["YawRate_YawRate"] for y in yaw])
    lat = np.array(latencies)
    ts = 1.0 / cfg.rate_hz
    if cfg.mode == "lockstep":
        delay = cfg.delay_steps
    else:
        # Measurement to application: the command's latency plus up to one plant step before the
        # actuator picks it up.
        delay = max(1, int(math.ceil(float(np.median(lat)) / ts))) if latencies else 1
    params = VehicleParams(v=sc.v, mu=sc.mu, mass=sc.mass)
    if cfg.controller == "none":
        stable = True
    else:
        poles = discrete_loop_poles(params, mr.configure(replace(ctrl, ts=ts)), delay)
        stable = bool(np.all(np.abs(poles) < 1.0))
    limit = mr.ControllerConfig().aux_limit
    summary = {
        "peak_aux_steer_deg": math.degrees(float(np.max(np.abs(aux)))),
        "final_aux_steer_deg": math.degrees(float(aux[-1])),
        "peak_yaw_rate_rad_s": float(np.max(np.abs(r))),
        "final_yaw_rate_rad_s": float(r[-1]),
        "saturated": bool(np.any(np.abs(aux) >= limit - 1e-6)),
        "stable": stable,
        "rate_hz": cfg.rate_hz,
        "delay_steps": delay,
        "mode": cfg.mode,
        "scenario": sc.name,
        "v": sc.v, "mu": sc.mu, "mass": sc.mass,
        "m_z": next((e.value for e in sc.events if e.kind == "yaw_moment"), 0.0),
        "controller": cfg.controller, "k": cfg.k, "tau": cfg.tau, "tau_n": cfg.tau_n,
        "model_delay_steps": cfg.model_delay,
        "duration": sc.duration,
        # Measurement frame to the command answering it (None without a controller).
        "latency_p50_s": float(np.median(lat)) if latencies else None,
        "latency_p99_s": float(np.percentile(lat, 99)) if latencies else None,
        "commands_answering_measurements": len(answered),
        "measurements": len(yaw),
    }
    return rows, summary


def _signals_csv(rows: list[dict[str, Any]]) -> bytes:
    import io

    columns: list[str] = ["t_s", "message", "e2e"]
    for r in rows:
        for k in r:
            if k not in columns:
                columns.append(k)
    buf = io.StringIO()
    w = csv.DictWriter(buf, columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.9g}" if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue().encode()


def _plot(rows: list[dict[str, Any]], summary: dict[str, Any]) -> bytes | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    import io

    yaw = [r for r in rows if r["message"] == "MRS_YawRate" and "YawRate_YawRate" in r]
    cmd = [r for r in rows if r["message"] == "MRS_AuxSteerCmd" and "AuxSteerCmd_Angle" in r]
    t0 = yaw[0]["t_s"] if yaw else 0.0
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    a1.plot([r["t_s"] - t0 for r in yaw], [r["YawRate_YawRate"] for r in yaw])
    a1.set_ylabel("yaw rate [rad/s]")
    a1.grid(True, alpha=0.3)
    a2.plot([r["t_s"] - t0 for r in cmd], [math.degrees(r["AuxSteerCmd_Angle"]) for r in cmd], color="C1")
    a2.set_ylabel("aux steering [deg]")
    a2.set_xlabel("time since first measurement [s]")
    a2.grid(True, alpha=0.3)
    fig.suptitle(f"HIL {summary['scenario']} ({summary['mode']}, {summary['rate_hz']:g} Hz, "
                 f"controller {summary['controller']})")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()
