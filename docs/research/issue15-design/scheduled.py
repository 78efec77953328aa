"""Scratch (issue 15 research): the proposed law, as the firmware would run it.

Structure "S1-scheduled": the model regulator of eq. (6) whose nominal model G_n holds the
actuator (first order, exact ZOH: it also holds the loop's one sample), the sensor's
Butterworth low-pass and the paper's first-order car (eq. 18); Q is eq. (22)'s first-order
limited-integrator filter, Tustin, as today.  K, tau and tau_n are scheduled on speed: the
coefficient sets are computed at configure time at speed breakpoints and interpolated linearly
in step().

`Law` below is a transcription target for model_regulator.py: configure() builds the tables,
step() is scalar, preallocated, call-free.  `law_ss(v)` is the same law, unsaturated, as a
reflib state space, used for every linear figure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import reflib as R

#: Calibration: speed breakpoints (m/s) and K, tau_Q = tau/(1+K) (s), tau_n (s) at each.
BREAKPOINTS = (5.0, 10.0, 20.0, 30.0, 40.0, 50.0)
CAL_K = (10.4, 27.0, 10.0, 10.0, 6.3, 4.5)
CAL_TAU_Q = (0.0048, 0.0090, 0.0056, 0.0136, 0.0128, 0.0141)
CAL_TAU_N = (0.0340, 0.0890, 0.1200, 0.2550, 0.2750, 0.3050)
TAU_A_MODEL = 0.020  # s, nominal actuator time constant
F_C_MODEL = 30.0  # Hz, nominal sensor low-pass (2nd-order Butterworth)


@dataclass(frozen=True)
class Cal:
    breakpoints: tuple[float, ...] = BREAKPOINTS
    k: tuple[float, ...] = CAL_K
    tau_q: tuple[float, ...] = CAL_TAU_Q
    tau_n: tuple[float, ...] = CAL_TAU_N
    tau_a_model: float = TAU_A_MODEL
    f_c_model: float = F_C_MODEL
    ts: float = R.TS


def butterworth2(f_c: float, ts: float) -> tuple[float, float, float, float, float]:
    """(b0, b1, b2, a1, a2) of the Tustin (pre-warped) 2nd-order Butterworth = scipy butter."""
    w = math.tan(math.pi * f_c * ts)
    n = 1.0 / (1.0 + math.sqrt(2.0) * w + w * w)
    b0 = w * w * n
    return b0, 2.0 * b0, b0, 2.0 * (w * w - 1.0) * n, (1.0 - math.sqrt(2.0) * w + w * w) * n


def q_coefficients(k: float, tau_q: float, tau_n: float, ts: float) -> tuple[float, ...]:
    """(a, g_w0, g_w1, g_r0, g_r1, q0): today's Tustin formulas (docs/controller.md)."""
    q0 = k / (1.0 + k)
    den = 2.0 * tau_q + ts
    return ((2.0 * tau_q - ts) / den, q0 * ts / den, q0 * ts / den,
            q0 * (2.0 * tau_n + ts) / den, q0 * (ts - 2.0 * tau_n) / den, q0)


def table(cal: Cal) -> list[tuple[float, ...]]:
    return [q_coefficients(k, tq, tn, cal.ts) for k, tq, tn in zip(cal.k, cal.tau_q, cal.tau_n)]


def interpolated(cal: Cal, v: float) -> tuple[float, ...]:
    """Coefficient set at speed v: linear between breakpoints, held outside them."""
    tab = table(cal)
    bp = cal.breakpoints
    if v <= bp[0]:
        return tab[0]
    if v >= bp[-1]:
        return tab[-1]
    j = max(i for i in range(len(bp) - 1) if bp[i] <= v)
    t = (v - bp[j]) / (bp[j + 1] - bp[j])
    return tuple((1 - t) * x0 + t * x1 for x0, x1 in zip(tab[j], tab[j + 1]))


def law_ss(v: float, cal: Cal = Cal()) -> R.SS:
    """The unsaturated law at speed v as a state space, inputs [m, u_sat], output u.

    States: [p_n, s1, s2, z] (model actuator position, Butterworth DF2T, Q recursion)."""
    a, gw0, gw1, gr0, gr1, _ = interpolated(cal, v)
    an = math.exp(-cal.ts / cal.tau_a_model)
    b0, b1, b2, a1, a2 = butterworth2(cal.f_c_model, cal.ts)
    ikn = R.inv_kn(v)
    # w = b0 p_n + s1 (delta_d = 0); y = gw0 w - gr0 ikn m + z
    A = np.zeros((4, 4))
    B = np.zeros((4, 2))
    w_row = np.array([b0, 1.0, 0.0, 0.0])
    y_row = gw0 * w_row + np.array([0.0, 0.0, 0.0, 1.0])
    y_m = -gr0 * ikn
    A[0, 0] = an
    B[0, 1] = 1.0 - an
    A[1] = b1 * np.array([1.0, 0, 0, 0]) - a1 * w_row + np.array([0, 0, 1.0, 0])
    A[2] = b2 * np.array([1.0, 0, 0, 0]) - a2 * w_row
    A[3] = gw1 * w_row + a * y_row
    B[3, 0] = -gr1 * ikn + a * y_m
    return R.SS(A, B, y_row[None, :], np.array([[y_m, 0.0]]))


class Law:
    """Scalar step() as the firmware would hold it (fault/fade/slew logic omitted here)."""

    def __init__(self, cal: Cal = Cal(), u_max: float = R.U_MAX) -> None:
        self.bp = cal.breakpoints
        self.inv_dv = [1.0 / (cal.breakpoints[i + 1] - cal.breakpoints[i]) for i in range(len(cal.breakpoints) - 1)]
        self.tab = table(cal)
        self.an = math.exp(-cal.ts / cal.tau_a_model)
        self.bn = 1.0 - self.an
        self.b0, self.b1, self.b2, self.a1, self.a2 = butterworth2(cal.f_c_model, cal.ts)
        self.u_max = u_max
        self.p_n = self.s1 = self.s2 = self.z = 0.0

    def step(self, delta_driver: float, yaw_rate: float, speed: float) -> float:
        rho = (R.WHEELBASE / speed + R.K_US * speed) * yaw_rate
        # coefficient set at this speed
        bp, tab = self.bp, self.tab
        if speed <= bp[0]:
            a, gw0, gw1, gr0, gr1, _ = tab[0]
        elif speed >= bp[-1]:
            a, gw0, gw1, gr0, gr1, _ = tab[-1]
        else:
            j = 0
            while speed >= bp[j + 1]:
                j += 1
            t = (speed - bp[j]) * self.inv_dv[j]
            c0, c1 = tab[j], tab[j + 1]
            a = c0[0] + t * (c1[0] - c0[0])
            gw0 = c0[1] + t * (c1[1] - c0[1])
            gw1 = c0[2] + t * (c1[2] - c0[2])
            gr0 = c0[3] + t * (c1[3] - c0[3])
            gr1 = c0[4] + t * (c1[4] - c0[4])
        # nominal model output: sensor model of (driver angle + modelled actuator position)
        x_in = delta_driver + self.p_n
        w = self.b0 * x_in + self.s1
        self.s1 = self.b1 * x_in - self.a1 * w + self.s2
        self.s2 = self.b2 * x_in - self.a2 * w
        y = gw0 * w - gr0 * rho + self.z
        u = y
        if u > self.u_max:
            u = self.u_max
        elif u < -self.u_max:
            u = -self.u_max
        self.z = gw1 * w - gr1 * rho + a * y
        self.p_n = self.an * self.p_n + self.bn * u  # model actuator, driven by the applied command
        return u
