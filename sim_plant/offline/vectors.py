"""Golden test vectors for ports of the controller (``mrsteer vectors --out DIR``).

For each configuration: ``<config>.cfg``, the calibration and the coefficient table as
``key = value`` lines (trivial to read from C). For each configuration and scenario:
``<config>__<scenario>.csv``, one row per step with the inputs, the command and the whole
state after the step.  Numbers are written with 17 significant digits (``repr``), so a float64
port can compare exactly and a reader gets back the very doubles the Python firmware used;
non-finite inputs are written ``nan``/``inf``/``-inf``.

The inputs come from two kinds of scenario:

* closed loop: the firmware driving the exactly discretised single-track model (section 3
  vehicle) with one sample of loop delay, so the inputs are what a car would send;
* synthetic: hand-made input sequences for the fault, inactivity and recovery paths,
  including NaN, infinities, out-of-range values and speeds below activation.

``secoc_setup.txt`` (``key = value`` lines) and ``secoc_frames.csv`` are vectors for a port of
the optional command authentication (``mrsteer_dbc.secoc``): a fixed key and clock, the sync
frames the actuator sends and the authenticated command frames that answer them, each with its
fields and its 8 bytes as they go on the bus, including the lost-commands and epoch-change paths.
"""

from __future__ import annotations

import csv
import io
import math
from collections import deque
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Callable, Iterator

from firmware_py import calibration_file
from firmware_py import model_regulator as mr
from firmware_py.platform.files import write_files
import mrsteer_dbc
from mrsteer_dbc import names, secoc
from sim_plant.car.vehicle import DiscretePlant, VehicleParams

Inputs = tuple[float, float, float]  # driver's front-wheel angle, yaw rate, speed


def _configs() -> dict[str, mr.ControllerConfig]:
    d = mr.ControllerConfig()
    paper = mr.PAPER_CONFIG
    return {
        "shipped_500hz": d,
        "previous_500hz": mr.PREVIOUS_CONFIG,
        "paper_limited_1khz": paper,
        "paper_standard_1khz": replace(paper, q_form=mr.Q_STANDARD),
        # constant gains with the nominal actuator and filter kept (ZOH of Q, 200 Hz)
        "limited_zoh_200hz_m1": replace(mr.constant_gains(d, 8.0, 0.03, mr.DEFAULT_TAU_N), ts=0.005,
                                        method=mr.METHOD_ZOH, model_filter_hz=20.0),
        # a three-point schedule, two samples modelled, a rate limit, the plain nominal model
        "limited_100hz_m2_ratelimit": replace(d, schedule_speed=(8.0, 16.0, 25.0), schedule_k=(4.0, 6.0, 3.0),
                                              schedule_tau=(0.02, 0.05, 0.03), schedule_tau_n=(0.02, 0.05, 0.1),
                                              model_actuator_tau=0.0, model_filter_hz=0.0, ts=0.01,
                                              model_delay_steps=2, rate_limit=math.radians(20.0)),
    }


CONFIGS = _configs()


def _closed_loop(cfg: mr.ControllerConfig, params: VehicleParams, duration: float,
                 m_z: Callable[[float], float], driver: Callable[[float], float]) -> Iterator[Inputs]:
    """Inputs the firmware sees while it drives the car (one sample of loop delay)."""
    plant = DiscretePlant(params, cfg.ts)
    c = mr.configure(cfg)
    s = mr.State()
    pipe: deque[float] = deque([0.0])
    for k in range(int(round(duration / cfg.ts)) + 1):
        t = k * cfg.ts
        dd = driver(t)
        r = float(plant.x[1])
        yield dd, r, params.v
        pipe.append(mr.step(c, s, dd, r, params.v))
        plant.advance(dd + pipe.popleft(), m_z(t))


def _synthetic_faults(cfg: mr.ControllerConfig) -> Iterator[Inputs]:
    """Every fault and inactivity path, each followed by recovery."""
    n = max(1, int(round(0.05 / cfg.ts)))  # 50 ms per phase

    def phase(count: int, f: Callable[[int], Inputs]) -> Iterator[Inputs]:
        for i in range(count):
            yield f(i)

    yield from phase(n, lambda i: (0.0, 0.0, 20.0))  # power-on, then active at rest
    yield from phase(4 * n, lambda i: (0.01, 0.3 * math.sin(0.2 * i), 20.0))  # active, saturating
    yield from phase(n, lambda i: (0.01, math.nan, 20.0))  # yaw rate NaN: fault, fade
    yield from phase(4 * n, lambda i: (0.01, 0.05, 20.0))  # recovery, slewing back
    yield from phase(n, lambda i: (0.9, 0.05, 20.0))  # driver angle out of range
    yield from phase(2 * n, lambda i: (0.0, 0.05, 20.0))
    yield from phase(n, lambda i: (0.0, 0.05, math.inf))  # speed infinite
    yield from phase(2 * n, lambda i: (0.0, 0.05, 20.0))
    yield from phase(n, lambda i: (0.0, -math.inf, -1.0))  # two faults at once
    yield from phase(2 * n, lambda i: (0.0, -0.05, 20.0))
    yield from phase(2 * n, lambda i: (0.0, -0.05, 20.0 - 9.0 * i / n))  # decelerating to 2 m/s: inactive
    yield from phase(n, lambda i: (0.0, -0.05, 2.0))  # inactive
    yield from phase(4 * n, lambda i: (0.0, -0.05, 2.0 + 8.0 * i / (4 * n)))  # accelerating again
    yield from phase(n, lambda i: (-0.02, 3.5, 10.0))  # yaw rate beyond +-3 rad/s


SCENARIOS: dict[str, Callable[[mr.ControllerConfig], Iterator[Inputs]]] = {
    "yaw_moment_step": lambda cfg: _closed_loop(cfg, VehicleParams(v=20.0, mu=1.0), 1.0,
                                                lambda t: 4000.0 if t >= 0.1 else 0.0, lambda t: 0.0),
    "saturating_low_mu": lambda cfg: _closed_loop(cfg, VehicleParams(v=30.0, mu=0.3, mass=1700.0), 1.0,
                                                  lambda t: 6000.0 if 0.1 <= t < 0.6 else 0.0, lambda t: 0.0),
    "driver_steer": lambda cfg: _closed_loop(cfg, VehicleParams(v=15.0, mu=0.8), 1.0, lambda t: 0.0,
                                             lambda t: 0.02 * min(1.0, max(0.0, (t - 0.1) / 0.2))),
    "faults_and_recovery": _synthetic_faults,
}

STATE_COLUMNS = ("z", "u_prev", *(f"u_hist{i}" for i in range(mr.MAX_MODEL_DELAY)), "hist_idx", "p_n", "f_s1",
                 "f_s2", "needs_init", "recovering", "status", "fault_flags")
COLUMNS = ("k", "delta_driver", "yaw_rate", "speed", "u", *STATE_COLUMNS)


def _num(x: float) -> str:
    return repr(float(x))  # 17 significant digits; 'nan', 'inf', '-inf'


def state_row(s: mr.State) -> list[str]:
    return [_num(s.z), _num(s.u_prev), *(_num(x) for x in s.u_hist), str(s.hist_idx), _num(s.p_n), _num(s.f_s1),
            _num(s.f_s2), str(int(s.needs_init)), str(int(s.recovering)), str(s.status), str(s.fault_flags)]


def _val(x: object) -> str:
    if isinstance(x, bool):
        return str(int(x))
    if isinstance(x, float):
        return _num(x)
    if isinstance(x, tuple):
        return ", ".join(_val(v) for v in x)
    return str(x)


def config_lines(cfg: mr.ControllerConfig) -> list[str]:
    """The calibration file (``calibration_file.dumps``), then every coefficient as ``c.name``."""
    c = mr.configure(cfg)
    return ["# calibration (ControllerConfig)", *calibration_file.dumps(cfg).splitlines(),
            "# coefficients (configure())", *(f"c.{f.name} = {_val(getattr(c, f.name))}" for f in fields(c))]


@dataclass(frozen=True)
class VectorSet:
    config: str
    scenario: str
    rows: int


def write_all(out: Path, progress: Callable[[str], None] | None = None) -> list[VectorSet]:
    """Write every configuration's .cfg and every (configuration, scenario) .csv into ``out``."""
    say = progress or (lambda m: None)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}
    written = []
    for name, cfg in CONFIGS.items():
        files[f"{name}.cfg"] = "\n".join(config_lines(cfg)) + "\n"
        for scen, make in SCENARIOS.items():
            c, s = mr.configure(cfg), mr.State()
            f = io.StringIO()
            w = csv.writer(f, lineterminator="\n")
            w.writerow(COLUMNS)
            n = 0
            for k, (dd, r, v) in enumerate(make(cfg)):
                u = mr.step(c, s, dd, r, v)
                w.writerow([str(k), _num(dd), _num(r), _num(v), _num(u), *state_row(s)])
                n += 1
            files[f"{name}__{scen}.csv"] = f.getvalue()
            written.append(VectorSet(name, scen, n))
            say(f"{name}__{scen}.csv: {n} steps")
    files.update(secoc_vectors())
    files.update(secoc_sensor_vectors())
    write_files(out, files)  # all or nothing: a port never sees a mixed set
    return written


def read_config(path: Path) -> mr.ControllerConfig:
    """The calibration back from a .cfg file (the coefficient lines are ignored)."""
    return calibration_file.load(path)


SECOC_KEY = bytes(range(16))
SECOC_T0 = secoc.EPOCH_ORIGIN_S + 1000.0  # the actuator's clock at its first sync
SECOC_COLUMNS = ("kind", "epoch", "fv_counter", "alive_counter", "state", "angle_rad", "meas_counter", "mac",
                 "sent", "frame_hex")


def secoc_vectors() -> dict[str, str]:
    """The authentication vectors: ``secoc_setup.txt`` (``key = value`` lines) and ``secoc_frames.csv``.

    ``sent`` is 0 for a command the signer produced but the bus lost (the actuator never saw it:
    its counter still advances), 1 otherwise.  Every sent command verifies at the actuator in
    file order; the syncs are what the actuator sent at the time the rows say."""
    contract = mrsteer_dbc.load()
    clock = [SECOC_T0]
    verifier = secoc.CommandVerifier(contract, SECOC_KEY, lambda: clock[0])
    signer = secoc.CommandSigner(contract, SECOC_KEY)
    alive = mrsteer_dbc.AliveCounter()
    lay = secoc.Layout.of(contract)
    rows: list[list[str]] = []

    def sync() -> None:
        data = verifier.next_sync()
        assert signer.accept_sync(data)
        rows.append(["sync", str(verifier.current), "", "", "", "", "", str(verifier.sync_mac(verifier.current)), "1",
                     data.hex()])

    def command(i: int, sent: bool = True) -> None:
        epoch, fv = signer.epoch, signer.counter
        values = {"AuxSteerCmd_State": mr.STATUS_ACTIVE if i % 7 else mr.STATUS_SATURATED,
                  "AuxSteerCmd_Angle": round(0.05 * math.sin(0.3 * i), 6), "AuxSteerCmd_MeasCounter": i % 15}
        counter = alive.next()
        data = signer.sign(values, counter)
        assert not sent or verifier.verify(lay.cmd_id, data, contract.decode(lay.cmd_id, data).signals)
        raw = contract.message(secoc.COMMAND).decode(data, decode_choices=False, scaling=False)
        rows.append(["cmd", str(epoch), str(fv), str(counter), str(values["AuxSteerCmd_State"]),
                     _num(values["AuxSteerCmd_Angle"]), str(values["AuxSteerCmd_MeasCounter"]),
                     str(raw[lay.mac]), str(int(sent)), data.hex()])

    sync()
    for i in range(20):  # past the 4-bit FV window and the alive counter's wrap
        command(i)
    for i in range(20, 35):  # 15 lost: the most the actuator bridges
        command(i, sent=False)
    for i in range(35, 40):
        command(i)
    clock[0] += 0.1
    sync()  # a new epoch: the counter starts at 0 again
    for i in range(40, 50):
        command(i)
    cfg = [f"key = {SECOC_KEY.hex()}", f"epoch_origin_s = {secoc.EPOCH_ORIGIN_S}", f"clock_s = {_num(SECOC_T0)}",
           f"command_id = {lay.cmd_id}", f"sync_id = {lay.sync_id}", f"mac_bits = {lay.mac_bits}",
           f"sync_mac_bits = {lay.sync_mac_bits}", f"fv_counter_low_bits = {lay.counter_low_bits}",
           f"counter_bits = {secoc.COUNTER_BITS}"]
    return {"secoc_setup.txt": "\n".join(cfg) + "\n", "secoc_frames.csv": _csv_text(SECOC_COLUMNS, rows)}


def _csv_text(columns: tuple[str, ...], rows: list[list[str]]) -> str:
    f = io.StringIO()
    w = csv.writer(f, lineterminator="\n")
    w.writerow(columns)
    w.writerows(rows)
    return f.getvalue()


SENSOR_COLUMNS = ("kind", "message", "epoch", "fv_counter", "alive_counter", "value", "mac", "sent", "frame_hex")
_SENSOR_SIGNAL = names.SENSOR_SIGNAL


def secoc_sensor_vectors() -> dict[str, str]:
    """``secoc_sensor_frames.csv``: the plant's signed sensor frames, with the syncs it sent.

    Per 2 ms cycle a driver-angle and a yaw-rate frame, a speed frame every 5th cycle.  20
    cycles, then 14 cycles the bus lost (``sent`` = 0: the most a receiver bridges), 5 more,
    a new epoch, and 10 more.  Every sent frame verifies in file order with the key of
    ``secoc_setup.txt``."""
    contract = mrsteer_dbc.load()
    clock = [SECOC_T0]
    master = secoc.CommandVerifier(contract, SECOC_KEY, lambda: clock[0])
    signer, check = secoc.SensorSigner(contract, SECOC_KEY), secoc.SensorVerifier(contract, SECOC_KEY)
    alive = {name: mrsteer_dbc.AliveCounter() for name in secoc.SENSORS}
    fv = dict.fromkeys(secoc.SENSORS, 0)
    rows: list[list[str]] = []

    def sync() -> None:
        data = master.next_sync()
        check.adopt(master.current)
        fv.update(dict.fromkeys(secoc.SENSORS, 0))
        rows.append(["sync", secoc.SYNC, str(master.current), "", "", "", str(master.sync_mac(master.current)), "1",
                     data.hex()])

    def cycle(i: int, sent: bool = True) -> None:
        values = {"MRS_DriverSteer": round(0.2 * math.sin(0.05 * i), 4), "MRS_YawRate": round(0.3 * math.cos(0.07 * i), 6),
                  "MRS_VehicleSpeed": round(20.0 + 0.01 * i, 3)}
        for name in secoc.SENSORS:
            if name == "MRS_VehicleSpeed" and i % 5:
                continue
            counter = alive[name].next()
            data = signer.sign(name, {_SENSOR_SIGNAL[name]: values[name]}, counter, master.current)
            decoded = contract.decode(contract.frame_id(name), data)
            assert not sent or check.verify(contract.frame_id(name), data, decoded.signals)
            fields = signer.fields[name]
            rows.append(["sensor", name, str(master.current), str(fv[name]), str(counter),
                         _num(round(decoded.signals[_SENSOR_SIGNAL[name]], 9)), str(int(decoded.signals[fields.mac])),
                         str(int(sent)), data.hex()])
            fv[name] += 1

    sync()
    for i in range(20):  # past the 3-bit FV wrap and the alive counter's wrap
        cycle(i)
    for i in range(20, 34):
        cycle(i, sent=False)
    for i in range(34, 39):
        cycle(i)
    clock[0] += 0.1
    sync()  # a new epoch: every message's counter starts at 0 again
    for i in range(39, 49):
        cycle(i)
    return {"secoc_sensor_frames.csv": _csv_text(SENSOR_COLUMNS, rows)}
