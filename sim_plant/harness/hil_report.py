"""What a HIL run produced, from its logged traffic: the decoded frames, the summary with the
keys of ``mrsteer sim disturbance``, the CSV of signals and the plot."""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

import mrsteer_dbc
from firmware_py import model_regulator as mr
from firmware_py.platform.files import write_files
from sim_plant.car import scenario as scn
from sim_plant.car.vehicle import VehicleParams
from sim_plant.harness.processes import RunError as HilError
from sim_plant.nodes.candump_log import Frame, read_candump
from sim_plant.offline.closed_loop import discrete_loop_poles

if TYPE_CHECKING:
    from sim_plant.harness.hil import HilConfig


@dataclass
class HilRun:
    """What ``run()`` produced."""

    summary: dict[str, Any]
    out: Path
    files: list[Path] = field(default_factory=list)


def finish(cfg: "HilConfig", sc: scn.Scenario, ctrl: mr.ControllerConfig, work: Path,
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


def summarize(frames: list[Frame], contract: mrsteer_dbc.Contract, cfg: "HilConfig", sc: scn.Scenario,
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
