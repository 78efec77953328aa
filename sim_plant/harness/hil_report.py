"""What a HIL run produced: from its logged traffic the decoded frames (``signals.csv``) and the
summary with the keys of ``mrsteer sim disturbance`` (``summary.json``); joined with the
plant's trace, one row per plant step (``steps.csv``, see ``hil_steps``) and the plot drawn
from those rows (``plot.png``).  Summary, table and plot cover the scenario's steps only."""

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
from sim_plant.car.nonlinear import spun, wrap_angle
from sim_plant.car.plants import NONLINEAR
from sim_plant.car.vehicle import VehicleParams
from sim_plant.harness import hil_plot, launch
from sim_plant.figures import resolution_of, tidy, tidy_figures
from sim_plant.harness.hil_caused_yaw import caused_yaw_figures
from sim_plant.harness.hil_timing import timing
from sim_plant.harness.log_time import scenario_times
from sim_plant.harness.hil_plausibility import plausibility_figures
from sim_plant.harness.hil_steps import Step, Traffic, read_plant_trace, state_names, step_table, steps_csv
from sim_plant.harness.processes import RunError as HilError
from sim_plant.nodes.candump_log import Frame, read_candump
from sim_plant.offline.closed_loop import discrete_loop_poles

if TYPE_CHECKING:
    from sim_plant.harness.hil import HilConfig


TRACE = "plant_trace.csv"  # in the run's work directory: the plant's true state at every step

@dataclass
class HilRun:
    """What ``run()`` produced."""

    summary: dict[str, Any]
    out: Path
    files: list[Path] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)  # one per plant step, as in steps.csv
    scenario: scn.Scenario | None = None


def finish(cfg: "HilConfig", sc: scn.Scenario, ctrl: mr.ControllerConfig, work: Path,
            say: Callable[[str], None]) -> HilRun:
    """Write the run's files from the work directory (``traffic.log``, ``plant_trace.csv`` and
    each process's statistics) to ``cfg.out``."""
    contract = mrsteer_dbc.load()
    frames = read_candump(work / "traffic.log")
    stats = {name: _load_json(work / f"{name}.json") for name in ("plant", "controller", "logger")}
    rows = decode(frames, contract)
    traffic = Traffic.of(rows, cfg.rate_hz)
    summary = summarize(traffic, cfg, sc, ctrl)
    steps = step_table(read_plant_trace(work / TRACE), traffic, cfg.mode == "lockstep", contract)
    summary["steps"] = len(steps)
    summary.update(car_figures(sc, steps))
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
    summary["plausibility"] = plausibility_figures(rows, sc, cfg.rate_hz, steps) | caused_yaw_figures(
        steps, sc, ctrl, cfg.rate_hz, lockstep=cfg.mode == "lockstep", delay_steps=cfg.delay_steps,
        controller=cfg.controller != "none", shipped=cfg.controller_program in (None, (str(launch.C_NODE),)))
    summary["loop"] = {"controller": stats["controller"], "plant": stats["plant"]}
    summary["timing"] = timing(summary["loop"], cfg.mode, cfg.rate_hz)
    summary = tidy_figures(summary)
    files = {
        "traffic.log": (work / "traffic.log").read_bytes(),
        "signals.csv": _signals_csv(frames, rows, cfg.rate_hz, contract),
        "steps.csv": steps_csv(steps),
        "summary.json": (json.dumps(summary, indent=2) + "\n").encode(),
    }
    png = hil_plot.run_png(steps, hil_plot.event_marks(sc), title(summary),
                           hil_plot.sensor_traces(steps, sc.sensor_config.faults))
    if png is not None:
        files["plot.png"] = png
    written = write_files(cfg.out, files)
    say(f"wrote {', '.join(files)} to {cfg.out}/")
    return HilRun(summary, cfg.out, written, steps, sc)


def title(summary: dict[str, Any]) -> str:
    """A run's figure title, from its summary."""
    return (f"HIL {summary['scenario']} ({summary['mode']}, {summary['rate_hz']:g} Hz, "
            f"controller {summary['controller']})")


def _load_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def decode(frames: list[Frame], contract: mrsteer_dbc.Contract) -> list[dict[str, Any]]:
    """Every logged frame decoded, with its E2E verdict: the rows of ``signals.csv``."""
    rows = []
    for f in frames:
        d = contract.decode(f.frame_id, f.data)
        if d is None:
            rows.append({"t_s": f.t, "message": f"0x{f.frame_id:X}", "e2e": "unknown"})
            continue
        rows.append({"t_s": f.t, "message": d.name, "e2e": d.status.value, **d.signals})
    return rows


def summarize(traffic: Traffic, cfg: "HilConfig", sc: scn.Scenario, ctrl: mr.ControllerConfig) -> dict[str, Any]:
    """The summary with the keys of ``mrsteer sim disturbance``, from the scenario's frames only:
    the plant's measurements and, in lockstep, the commands answering them; in realtime, the
    commands sent while the plant ran."""
    yaw, cmds = traffic.yaw, traffic.commands
    if not yaw:
        raise HilError("no yaw-rate frames on the bus: the plant never published")
    t0, t_end = yaw[0]["t_s"], yaw[-1]["t_s"]
    pairs = [(y, cmds[a]) for y, a in zip(yaw, traffic.answers) if a is not None]
    answered = [c for _, c in pairs]
    latencies = [c["t_s"] - y["t_s"] for y, c in pairs]
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
        stable: bool | None = True
    elif not sc.ideal_car:
        stable = None  # the pole analysis is of the paper's ideal loop, not of this car's
    else:
        poles = discrete_loop_poles(params, mr.configure(replace(ctrl, ts=ts)), delay)
        stable = bool(np.all(np.abs(poles) < 1.0))
    limit = mr.ControllerConfig().aux_limit
    return {
        "peak_aux_steer_deg": math.degrees(float(np.max(np.abs(aux)))),
        "final_aux_steer_deg": math.degrees(float(aux[-1])),
        # the measured yaw rate (car_figures makes peak_yaw_rate_rad_s the car's true one)
        "peak_yaw_rate_rad_s": float(np.max(np.abs(r))),
        "peak_measured_yaw_rate_rad_s": float(np.max(np.abs(r))),
        "final_yaw_rate_rad_s": float(r[-1]),  # the car's true one replaces it (car_figures)
        "final_measured_yaw_rate_rad_s": float(r[-1]),
        "saturated": bool(np.any(np.abs(aux) >= limit - 1e-6)),
        "stable": stable,
        "rate_hz": cfg.rate_hz,
        "delay_steps": delay,
        "mode": cfg.mode,
        "scenario": sc.name,
        "v": sc.v, "mu": sc.mu, "mass": sc.mass,
        "m_z": next((e.value for e in sc.events if e.kind == "yaw_moment"), 0.0),
        "controller": cfg.controller, **{k: v for k, v in mr.describe_gains(ctrl).items() if k != "q_form"},
        "duration": sc.duration,
        # Measurement frame to the command answering it (None without a controller).
        "latency_p50_s": float(np.median(lat)) if latencies else None,
        "latency_p99_s": float(np.percentile(lat, 99)) if latencies else None,
        "commands_answering_measurements": len(answered),
        "measurements": len(yaw),
    }


def car_figures(sc: scn.Scenario, steps: list[Step]) -> dict[str, Any]:
    """The car the run used and what it did, from the plant's true states (``steps.csv``), as a
    campaign defines them (``campaign.engine.METRICS``): the true yaw rate's peak and final
    value (``peak_yaw_rate_rad_s``, ``final_yaw_rate_rad_s``; the bus's measured ones are
    ``peak_measured_yaw_rate_rad_s``, ``final_measured_yaw_rate_rad_s``), the
    side slip's peak (wrapped to (-180, 180] deg), the auxiliary command's RMS, the time the
    controller reported the state SATURATED, and the speed at the end.  A car that spun
    (``nonlinear.spun``: ``spun``, at ``spin_time_s``) left its model there: these figures are
    those up to that step, as a campaign's run ends there."""
    ts = steps[1].t_s - steps[0].t_s if len(steps) > 1 else 0.0
    # (only the nonlinear car has a model that ends: the linear one's equations are the car's)
    end = next((k for k, s in enumerate(steps) if spun(s.beta_rad)), None) if sc.plant == NONLINEAR else None
    steps = steps if end is None else steps[:end + 1]
    cmd = np.array([s.aux_cmd_rad for s in steps] or [0.0])
    saturated = state_names()[mr.STATUS_SATURATED]
    true_peak = {"peak_yaw_rate_rad_s": max(abs(s.yaw_rate_rad_s) for s in steps),
                 "final_yaw_rate_rad_s": steps[-1].yaw_rate_rad_s} if steps else {}
    return {
        **true_peak,
        "spun": end is not None,
        "spin_time_s": None if end is None else steps[-1].t_s,
        "plant": sc.plant,
        "actuator": "ideal" if sc.actuator.order == 0 and sc.actuator.dead_time_samples == 0 else
                    f"order {sc.actuator.order}, {1e3 * sc.actuator.time_constant_s:g} ms" if sc.actuator.order == 1
                    else f"order {sc.actuator.order}, {sc.actuator.natural_frequency_hz:g} Hz",
        "sensors": "ideal" if sc.sensors.exact else (f"{sc.sensors.yaw_rate.noise_density:g} deg/s/rtHz, "
                                                      f"{sc.sensors.yaw_rate.lowpass_hz:g} Hz low-pass"),
        "seed": None if sc.sensors.exact else sc.sensors.seed,
        "peak_side_slip_deg": math.degrees(max((abs(wrap_angle(s.beta_rad)) for s in steps), default=0.0)),
        "aux_rms_deg": math.degrees(float(np.sqrt(np.mean(cmd * cmd)))),
        "time_at_limit_s": sum(s.ctrl_state == saturated for s in steps) * ts,
        "final_speed_m_s": steps[-1].v_m_s if steps else sc.v,
    }


def _signals_csv(frames: list[Frame], rows: list[dict[str, Any]], rate_hz: float,
                 contract: mrsteer_dbc.Contract) -> bytes:
    """Every frame decoded: its scenario time first (``log_time``), then its bus time (epoch s, to
    the log's microsecond), each signal at its DBC resolution."""
    columns: list[str] = ["t_s", "bus_time_s", "message", "e2e"]
    for r in rows:
        for k in r:
            if k not in columns:
                columns.append(k)
    times = scenario_times([(f.frame_id, f.data, f.t) for f in frames], 1.0 / rate_hz, contract)
    buf = io.StringIO()
    w = csv.DictWriter(buf, columns, lineterminator="\n")
    w.writeheader()
    for t, r in zip(times, rows):
        scales = _scales(contract, r["message"])
        w.writerow({"t_s": repr(tidy(t, resolution_of("t_s"))), "bus_time_s": f"{r['t_s']:.6f}",
                    **{k: (repr(tidy(v, scales.get(k))) if isinstance(v, float) else v)
                       for k, v in r.items() if k != "t_s"}})
    return buf.getvalue().encode()


def _scales(contract: mrsteer_dbc.Contract, message: str) -> dict[str, float]:
    """The DBC scale of each signal of ``message`` (none for a frame not in the DBC)."""
    try:
        return {s.name: float(s.scale) for s in contract.message(message).signals}
    except KeyError:
        return {}


def recorded_controller(log: Path) -> tuple[str | None, float | None]:
    """(trigger, rate in Hz) of the controller that a ``hil run``'s ``summary.json`` beside
    ``log`` describes (lockstep mode: the ``sensors`` trigger, realtime: ``clock``); (None, None)
    for a log with no readable summary beside it (a ``candump -L`` from elsewhere)."""
    try:
        summary = json.loads((log.parent / "summary.json").read_text())
        mode, rate = summary["mode"], float(summary["rate_hz"])
    except (OSError, ValueError, KeyError, TypeError):
        return None, None
    trigger = {"lockstep": "sensors", "realtime": "clock"}.get(mode)
    return trigger, (rate if trigger is not None and math.isfinite(rate) and rate > 0.0 else None)
