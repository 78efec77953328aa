"""Scratch (issue 15 research): the reference loop and every figure of the constraint set.

Reference loop (issue 15, item 2): 500 Hz; the command computed at step k is applied over step
k+1 through a first-order actuator discretised as the product's PositionActuator does
(p[k+1] = a p[k] + (1-a) clamp(u[k]), a = exp(-Ts/tau_a); the plant applies p[k] over step k),
which with tau_a -> 0 is exactly one sample of delay; the paper's single-track car (eqs. 14/16,
exact ZOH); a 2nd-order Butterworth 30 Hz low-pass on the measured yaw rate (scipy butter at
500 Hz, direct feed-through, as sim_plant.car.sensors).

A controller is a discrete state space with inputs [m, u_sat] (m the filtered measured yaw rate
in rad/s, u_sat the applied = clamped command it feeds back) and output u (rad):
    xc[k+1] = Ac xc + Bm m + Bu u_sat,   u = Cc xc + Dm m     (no feed-through from u_sat).
Not product code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.linalg import expm, solve_discrete_lyapunov

TS = 0.002
FS = 1.0 / TS
L_F, L_R, J = 1.25, 1.32, 1750.0
C_F0, C_R0 = 84000.0, 96000.0
M_NOM = 1296.0
U_MAX = math.radians(3.0)
NOISE_DENSITY = math.radians(0.014)  # rad/s/sqrt(Hz), one-sided
NOISE_SIGMA = NOISE_DENSITY * math.sqrt(FS / 2.0)  # per-sample sigma of the white yaw-rate noise
BUT_B, BUT_A = signal.butter(2, 30.0, fs=FS)
TAU_A = 0.020

WHEELBASE = L_F + L_R
K_US = (C_R0 * L_R - C_F0 * L_F) * M_NOM / (C_F0 * C_R0 * WHEELBASE)


def inv_kn(v: float) -> float:
    """1/K_n(v) of eq. (15) for the nominal car (as the firmware computes it)."""
    return WHEELBASE / v + K_US * v


@dataclass
class SS:
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray


def plant(v: float, mu: float, m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZOH single-track model: Phi, Gamma_delta, Gamma_Mz (state [beta, r])."""
    cf, cr = mu * C_F0, mu * C_R0
    a11 = -(cf + cr) / (m * v)
    a12 = (cr * L_R - cf * L_F) / (m * v * v) - 1.0
    a21 = (cr * L_R - cf * L_F) / J
    a22 = -(cf * L_F**2 + cr * L_R**2) / (J * v)
    A = np.array([[a11, a12], [a21, a22]])
    B = np.array([[cf / (m * v), 0.0], [cf * L_F / J, 1.0 / J]])
    aug = np.zeros((4, 4))
    aug[:2, :2] = A
    aug[:2, 2:] = B
    e = expm(aug * TS)
    return e[:2, :2], e[:2, 2], e[:2, 3]


def tf_ss(num, den) -> SS:
    """Discrete TF (z polynomials, highest power first) -> SS (proper)."""
    A, B, C, D = signal.tf2ss(num, den)
    return SS(A, B, C, D)


SENSOR = tf_ss(BUT_B, BUT_A)
_IDEAL_SENSOR = SS(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), np.ones((1, 1)))


def set_sensor(ideal: bool) -> None:
    """Swap the yaw-rate low-pass for an exact sensor (to reproduce the ideal-loop figures)."""
    global SENSOR
    SENSOR = _IDEAL_SENSOR if ideal else tf_ss(BUT_B, BUT_A)


def sensor_response(z):
    if SENSOR is _IDEAL_SENSOR:
        return np.ones_like(z)
    return np.polyval(BUT_B, z) / np.polyval(BUT_A, z)


def closed_loop(v, mu, m, ctrl: SS, tau_a=TAU_A, extra_delay=0, gain: complex = 1.0):
    """Unsaturated closed loop. Returns (A, B_n, B_Mz, C_u, D_un, C_r).

    State: [beta, r, p, delay line (extra_delay), sensor filter (2), controller].
    ``gain`` multiplies the command on its way to the actuator (loop broken at the actuator
    input); the controller's own feedback input u_sat stays the unperturbed command.
    """
    phi, gd, gm = plant(v, mu, m)
    a = math.exp(-TS / tau_a) if tau_a > 0 else 0.0
    nf = SENSOR.A.shape[0]
    nc = ctrl.A.shape[0]
    nd = extra_delay
    n = 3 + nd + nf + nc
    dt = complex if isinstance(gain, complex) and gain.imag != 0 else float
    A = np.zeros((n, n), dtype=dt)
    Bn = np.zeros(n, dtype=dt)
    BM = np.zeros(n)
    ip, idl, i_f, ic = 2, 3, 3 + nd, 3 + nd + nf
    # measurement m = Cf xf + Df (r + noise); command u = Cc xc + Dm m
    Cf, Df = SENSOR.C[0], SENSOR.D[0, 0]
    Cc, Dm = ctrl.C[0], ctrl.D[0, 0]
    Bm, Bu = ctrl.B[:, 0], ctrl.B[:, 1]
    # u as a row over the state, and its noise feed-through
    urow = np.zeros(n)
    urow[i_f:i_f + nf] = Dm * Cf
    urow[1] += Dm * Df
    urow[ic:] += Cc
    u_n = Dm * Df
    # plant
    A[0:2, 0:2] = phi
    A[0:2, ip] = gd
    BM[0:2] = gm
    # actuator input: g u (delayed by the line)
    A[ip, ip] = a
    if nd == 0:
        A[ip, :] += (1 - a) * gain * urow
        Bn[ip] += (1 - a) * gain * u_n
    else:
        A[ip, idl + nd - 1] += (1 - a)
        A[idl, :] += gain * urow
        Bn[idl] += gain * u_n
        for j in range(1, nd):
            A[idl + j, idl + j - 1] = 1.0
    # sensor filter, input r + n
    A[i_f:i_f + nf, i_f:i_f + nf] = SENSOR.A
    A[i_f:i_f + nf, 1] += SENSOR.B[:, 0]
    Bn[i_f:i_f + nf] += SENSOR.B[:, 0]
    # controller: inputs m and u (unsaturated: u_sat = u)
    mrow = np.zeros(n)
    mrow[i_f:i_f + nf] = Cf
    mrow[1] = Df
    A[ic:, ic:] += ctrl.A
    A[ic:, :] += np.outer(Bm, mrow) + np.outer(Bu, urow)
    Bn[ic:] += Bm * Df + Bu * u_n
    Cr = np.zeros(n)
    Cr[1] = 1.0
    return A, Bn, BM, urow, u_n, Cr


def radius(A) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(A))))


def noise_rms_deg(v, mu, m, ctrl, tau_a=TAU_A) -> float:
    """Exact H2: RMS of the command u from white yaw-rate noise of NOISE_SIGMA per sample."""
    A, Bn, _, Cu, Dun, _ = closed_loop(v, mu, m, ctrl, tau_a)
    if radius(A) >= 1.0:
        return math.inf
    X = solve_discrete_lyapunov(A, np.outer(Bn, Bn))
    var = Cu @ X @ Cu + Dun * Dun
    return math.degrees(math.sqrt(var) * NOISE_SIGMA)


def freq_loop(v, mu, m, ctrl: SS, w: np.ndarray, tau_a=TAU_A) -> np.ndarray:
    """L(e^{jwT}) = -[C_m / (1 - C_u)] F P A, broken at the actuator input."""
    z = np.exp(1j * w * TS)
    phi, gd, _ = plant(v, mu, m)
    a = math.exp(-TS / tau_a) if tau_a > 0 else 0.0
    (p00, p01), (p10, p11) = phi
    Pr = ((z - p00) * gd[1] + p10 * gd[0]) / ((z - p00) * (z - p11) - p01 * p10)
    Aact = (1 - a) / (z - a)
    F = sensor_response(z)
    nc = ctrl.A.shape[0]
    M = z[:, None, None] * np.eye(nc)[None] - ctrl.A[None]
    X = np.linalg.solve(M, np.broadcast_to(ctrl.B, (len(z),) + ctrl.B.shape))
    Cm = X[:, :, 0] @ ctrl.C[0] + ctrl.D[0, 0]
    Cu = X[:, :, 1] @ ctrl.C[0]
    return -(Cm / (1.0 - Cu)) * F * Pr * Aact


W_GRID = np.concatenate([np.geomspace(0.05, math.pi / TS, 1500, endpoint=False), [math.pi / TS]])


def margins(v, mu, m, ctrl: SS) -> tuple[float, float]:
    """(gain margin dB: smallest |20 log|L|| over phase crossovers, phase margin deg)."""
    Lw = freq_loop(v, mu, m, ctrl, W_GRID)
    gm = math.inf
    im = Lw.imag
    for i in np.flatnonzero(np.signbit(im[:-1]) != np.signbit(im[1:])):
        t = im[i] / (im[i] - im[i + 1])
        Lx = Lw[i] + t * (Lw[i + 1] - Lw[i])
        if Lx.real < 0:
            gm = min(gm, abs(20 * math.log10(abs(Lx.real))))
    if Lw[-1].real < 0:
        gm = min(gm, abs(20 * math.log10(abs(Lw[-1].real))))
    pm = math.inf
    lg = np.log(np.abs(Lw))
    for i in np.flatnonzero(np.signbit(lg[:-1]) != np.signbit(lg[1:])):
        t = lg[i] / (lg[i] - lg[i + 1])
        Lx = Lw[i] + t * (Lw[i + 1] - Lw[i])
        pm = min(pm, 180.0 - abs(math.degrees(np.angle(Lx))))
    return gm, pm


def perturbed_stable(v, mu, m, ctrl) -> dict[str, float]:
    """Pole radii of the loop with the perturbations the constraints name."""
    out = {"nominal": radius(closed_loop(v, mu, m, ctrl)[0])}
    out["gain"] = max(radius(closed_loop(v, mu, m, ctrl, gain=g)[0]) for g in (0.5, 0.7, 1.4, 2.0))
    out["phase"] = max(radius(closed_loop(v, mu, m, ctrl, gain=complex(np.exp(1j * math.radians(p))))[0])
                       for p in (-45, -30, -15, 15, 30, 45))
    out["delay"] = radius(closed_loop(v, mu, m, ctrl, extra_delay=1)[0])
    out["tau_a"] = max(radius(closed_loop(v, mu, m, ctrl, tau_a=t)[0]) for t in (0.010, 0.0141, 0.028, 0.040))
    return out


def simulate(v, mu, m, ctrl: SS, mz: float, n_steps: int, tau_a=TAU_A, extra_delay=0,
             noise: np.ndarray | None = None):
    """Nonlinear run (command clamped to +-3 deg, applied command fed back). Step of mz at k=0.

    Returns (r, u_command_clamped, p_applied) arrays."""
    phi, gd, gm = plant(v, mu, m)
    a = math.exp(-TS / tau_a) if tau_a > 0 else 0.0
    x = np.zeros(2)
    p = 0.0
    line = [0.0] * extra_delay
    xf = np.zeros(SENSOR.A.shape[0])
    xc = np.zeros(ctrl.A.shape[0])
    Af, Bf, Cf, Df = SENSOR.A, SENSOR.B[:, 0], SENSOR.C[0], SENSOR.D[0, 0]
    Ac, Bm, Bu, Cc, Dm = ctrl.A, ctrl.B[:, 0], ctrl.B[:, 1], ctrl.C[0], ctrl.D[0, 0]
    rs = np.empty(n_steps)
    us = np.empty(n_steps)
    ps = np.empty(n_steps)
    for k in range(n_steps):
        r = x[1]
        meas = r + (noise[k] if noise is not None else 0.0)
        mf = Cf @ xf + Df * meas
        xf = Af @ xf + Bf * meas
        u = Cc @ xc + Dm * mf
        u = min(U_MAX, max(-U_MAX, u))
        xc = Ac @ xc + Bm * mf + Bu * u
        rs[k], us[k], ps[k] = r, u, p
        x = phi @ x + gd * p + gm * mz
        if extra_delay:
            line.append(u)
            u_in = line.pop(0)
        else:
            u_in = u
        p = a * p + (1 - a) * u_in
    return rs, us, ps


def peak_yaw(v, ctrl, mz=4000.0, t=1.5, mu=1.0, m=M_NOM) -> float:
    r, _, _ = simulate(v, mu, m, ctrl, mz, int(t / TS))
    return float(np.max(np.abs(r)))


def reaches_limit(v, ctrl, mz, t=3.0) -> bool:
    _, _, p = simulate(v, 1.0, M_NOM, ctrl, mz, int(t / TS))
    return bool(np.max(np.abs(p)) >= 0.99 * U_MAX)


def sat_threshold(v, ctrl, lo=1000.0, hi=20000.0, tol=2.0) -> float:
    """Smallest M_z step (Nm) after which the applied aux angle reaches 99 % of 3 deg."""
    if not reaches_limit(v, ctrl, hi):
        return hi
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if reaches_limit(v, ctrl, mid):
            hi = mid
        else:
            lo = mid
    return hi
