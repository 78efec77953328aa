"""Micro-benchmarks: the firmware step and the receive path, each against a baseline."""

from __future__ import annotations

import math
from typing import Any

import can
import numpy as np

import mrsteer_dbc
from mrsteer_dbc import names
from firmware_py import model_regulator as mr
from firmware_py.controller import node as rt
from mrsteer_bench.timer import per_call_us


class NumpyRegulator:
    """The firmware's law written the way array code would write it (the baseline): state,
    coefficient tables and limits in numpy arrays, the schedule with ``np.interp``, range checks
    and clamp with numpy functions.  The same law as ``model_regulator.step`` on the active
    path with M >= 1 (to rounding: np.interp's arithmetic is its own)."""

    def __init__(self, c: mr.Coefficients) -> None:
        if c.model_delay < 1:
            raise ValueError("the baseline implements the modelled-delay law (M >= 1)")
        self.v = np.array(c.sched_v)
        self.tables = np.array([c.sched_g_w0, c.sched_g_w1, c.sched_g_r0, c.sched_g_r1, c.sched_a])
        self.model = np.array([c.act_a, c.act_b, c.flt_b0, c.flt_b1, c.flt_b2, c.flt_a1, c.flt_a2])
        self.limits = np.array([c.driver_angle_max, c.yaw_rate_max, c.speed_max])
        self.u_lim = np.array([-c.u_max, c.u_max])
        self.sched = np.array([c.wheelbase, c.k_us])
        self.x = np.zeros(4)  # z, p_n, s1, s2
        self.hist = np.zeros(c.model_delay)
        self.idx = 0
        self.m = c.model_delay
        self.v_min = c.speed_active_min

    def step(self, delta_driver: float, yaw_rate: float, speed: float) -> float:
        x = np.array([delta_driver, yaw_rate, speed])
        if not (np.all(np.abs(x) <= self.limits) and speed >= self.v_min):
            return 0.0
        rho = (self.sched[0] / speed + self.sched[1] * speed) * yaw_rate
        g = np.array([np.interp(speed, self.v, t) for t in self.tables])
        an, bn, b0, b1, b2, a1, a2 = self.model
        st = self.x
        st[1] = an * st[1] + bn * self.hist[self.idx]
        xin = delta_driver + st[1]
        w = b0 * xin + st[2]
        st[2] = b1 * xin - a1 * w + st[3]
        st[3] = b2 * xin - a2 * w
        y = g[0] * w - g[2] * rho + st[0]
        u = float(np.clip(y, self.u_lim[0], self.u_lim[1]))
        self.hist[self.idx] = u
        self.idx = (self.idx + 1) % self.m
        st[0] = g[1] * w - g[3] * rho + g[4] * y
        return u


def firmware_step(quick: bool) -> dict[str, Any]:
    cfg = mr.ControllerConfig()
    c = mr.configure(cfg)
    s = mr.State()
    mr.step(c, s, 0.0, 0.0, 20.0)  # leave the power-on state
    base = NumpyRegulator(c)
    # Equivalence on a short run before timing anything.
    s2 = mr.State()
    mr.step(c, s2, 0.0, 0.0, 20.0)
    base.step(0.0, 0.0, 20.0)
    worst = 0.0
    for k in range(2000):
        r = 0.05 * math.sin(0.01 * k)
        worst = max(worst, abs(mr.step(c, s2, 0.01, r, 20.0) - base.step(0.01, r, 20.0)))
    step = mr.step
    calls, repeats = (2000, 15) if quick else (20000, 31)
    ours = per_call_us(lambda: step(c, s, 0.01, 0.05, 20.0), calls, repeats)
    numpy_ = per_call_us(lambda: base.step(0.01, 0.05, 20.0), calls // 4, repeats)
    return {"name": "firmware step()", "ours": ours, "baseline": numpy_, "baseline_name": "same law with numpy arrays",
            "speedup": numpy_["median_us"] / ours["median_us"], "max_abs_difference_rad": worst,
            "target": "median <= 2 us and >= 5x faster than numpy"}


def receive_path(quick: bool) -> dict[str, Any]:
    contract = mrsteer_dbc.load()
    bus = can.Bus(interface="virtual", channel="mrsteer-bench-rx", receive_own_messages=False)
    try:
        node = rt.ControllerNode(bus, rt.RuntimeConfig(), contract)
        name = names.MSG_YAW
        fid = contract.frame_id(name)
        frames = [can.Message(arbitration_id=fid, is_extended_id=False,
                              data=contract.encode(name, {"YawRate_YawRate": 0.1}, k))
                  for k in range(mrsteer_dbc.COUNTER_MODULO)]
        it = [0]

        def ours() -> None:
            i = it[0]
            node.receive(frames[i])
            it[0] = i + 1 if i + 1 < len(frames) else 0

        before = node.stats.rx_rejected
        calls, repeats = (1500, 15) if quick else (15000, 31)
        mine = per_call_us(ours, calls, repeats)
        rejected = node.stats.rx_rejected - before
        db = contract.db
        data = bytes(frames[3].data)
        alone = per_call_us(lambda: db.decode_message(fid, data), calls, repeats)
    finally:
        bus.shutdown()
    return {"name": "receive path per frame", "ours": mine, "baseline": alone,
            "baseline_name": "cantools Database.decode_message alone",
            "ratio_to_baseline": mine["median_us"] / alone["median_us"], "frames_rejected": rejected,
            "target": "median <= 10 us (decode + range + E2E CRC + counter)"}
