"""Scratch (issue 15 research): controller structures as state spaces for reflib.

Each builder returns reflib.SS with inputs [m, u_sat] and output u, at one speed v (the
controller is scheduled on v through 1/K_n(v) and, for scheduled designs, its parameters).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

import reflib as R


def _stack(parts) -> R.SS:
    """u = sum of SISO blocks; parts = [(ss, input index 0=m / 1=u_sat, sign)]."""
    n = sum(p[0].A.shape[0] for p in parts)
    A = np.zeros((n, n))
    B = np.zeros((n, 2))
    C = np.zeros((1, n))
    D = np.zeros((1, 2))
    i = 0
    for ss, inp, sign in parts:
        k = ss.A.shape[0]
        A[i:i + k, i:i + k] = ss.A
        B[i:i + k, inp] = ss.B[:, 0]
        C[0, i:i + k] = sign * ss.C[0]
        D[0, inp] += sign * ss.D[0, 0]
        i += k
    if abs(D[0, 1]) > 1e-15:
        raise ValueError("algebraic loop: the u_sat path must be strictly proper")
    return R.SS(A, B, C, D)


def _tf(num, den) -> R.SS:
    num = np.atleast_1d(np.asarray(num, float))
    den = np.atleast_1d(np.asarray(den, float))
    if len(den) == 1:  # static gain
        return R.SS(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), np.array([[num[-1] / den[0]]]))
    return R.tf_ss(num, den)


def shipped(v: float, k=43.0, tau=0.0212, tau_n=0.02, m_delay=1) -> R.SS:
    """The firmware's law today (limited Q of eq. 22, Tustin, w = u_sat delayed M steps)."""
    tau_q = tau / (1 + k)
    q0 = k / (1 + k)
    nq, dq = signal.bilinear([q0], [tau_q, 1.0], fs=R.FS)
    nr, dr = signal.bilinear([q0 * tau_n, q0], [tau_q, 1.0], fs=R.FS)
    nw = np.polymul(nq, [1.0])
    dw = np.polymul(dq, [1.0] + [0.0] * m_delay)
    ikn = R.inv_kn(v)
    return _stack([(_tf(nw, dw), 1, 1.0), (_tf(np.asarray(nr) * ikn, dr), 0, -1.0)])


def q0_poly(k: float, tau_q: float, order: int, c: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Q0(s) = q0 (1 + c1 tau_q s + c2 (tau_q s)^2 ...) / (tau_q s + 1)^order, q0 = K/(1+K)."""
    q0 = k / (1.0 + k)
    num = np.array([1.0])
    for j, cj in enumerate(c, start=1):
        term = np.zeros(j + 1)
        term[0] = cj * tau_q**j
        num = np.polyadd(num, term)
    den = np.array([1.0])
    for _ in range(order):
        den = np.polymul(den, [tau_q, 1.0])
    return q0 * num, den


def laglead(k: float, tau_q: float, alpha: float, t_l: float):
    """Q0(s) = q0 (alpha T s + 1) / ((T s + 1)(tau_q s + 1)): eq. (21) with a lag-lead R(s);
    its gain falls from q0 (d.c.) to alpha q0 above 1/T, before the roll-off at 1/tau_q."""
    q0 = k / (1.0 + k)
    return q0 * np.array([alpha * t_l, 1.0]), np.polymul([t_l, 1.0], [tau_q, 1.0])


def s1(v: float, k: float, tau_q: float, tau_n: float, order: int = 1, c=(), tau_an=R.TAU_A,
       filt_model=True, m_extra=0, q=None) -> R.SS:
    """Model regulator whose nominal model holds the actuator, the sensor filter and the delay:

        u = Q0 [ F_n A_n u_sat ] - Q0 (tau_n s + 1) [ rho ],   rho = m / K_n(v)

    F_n: the sensor's Butterworth, A_n = (1-a_n)/(z-a_n) (holds the loop's one sample),
    Q0 of eq. (12) form with d.c. gain K/(1+K) (eq. 22), both Q0 paths Tustin."""
    nq, dq = q0_poly(k, tau_q, order, c)
    nqz, dqz = signal.bilinear(nq, dq, fs=R.FS)
    nrz, drz = signal.bilinear(np.polymul(nq, [tau_n, 1.0]), dq, fs=R.FS)
    a_n = math.exp(-R.TS / tau_an) if tau_an > 0 else 0.0
    nw, dw = np.polymul(nqz, [1 - a_n]), np.polymul(dqz, [1.0, -a_n])
    if filt_model:
        nw, dw = np.polymul(nw, R.BUT_B), np.polymul(dw, R.BUT_A)
    if m_extra:
        dw = np.polymul(dw, [1.0] + [0.0] * m_extra)
    ikn = R.inv_kn(v)
    return _stack([(_tf(nw, dw), 1, 1.0), (_tf(np.asarray(nrz) * ikn, drz), 0, -1.0)])


def s2(v: float, k: float, tau_q: float, tau_n: float = 0.0, order: int = 1, c=(), tau_an=R.TAU_A, q=None) -> R.SS:
    """As s1, but the nominal car is eq. (14) itself at mu = 1 and the nominal mass, normalised
    to unit d.c. gain (P_n = G_r,delta(s) / K_n(v)), times an optional extra lag 1/(tau_n s + 1):

        u = Q0 [ F_n A_n u_sat ] - Q0 / P_n [ rho ]."""
    m, cf, cr = R.M_NOM, R.C_F0, R.C_R0
    b0 = cf * cr * R.WHEELBASE * v
    b1 = cf * R.L_F * m * v * v
    a0 = cf * cr * R.WHEELBASE**2 + (cr * R.L_R - cf * R.L_F) * m * v * v
    a1 = (cf * (R.J + R.L_F**2 * m) + cr * (R.J + R.L_R**2 * m)) * v
    a2 = R.J * m * v * v
    kn = b0 / a0
    # 1/P_n = (a2 s^2 + a1 s + a0) kn / (b1 s + b0) = (a2 s^2 + a1 s + a0)/a0 / ((b1/b0) s + 1)
    inv_num = np.polymul(np.array([a2, a1, a0]) / a0, [tau_n, 1.0])
    inv_den = np.array([b1 / b0, 1.0])
    nq, dq = q0_poly(k, tau_q, order, c) if q is None else q
    nqz, dqz = signal.bilinear(nq, dq, fs=R.FS)
    nr, dr = np.polymul(nq, inv_num), np.polymul(dq, inv_den)
    if len(nr) > len(dr):
        raise ValueError("Q0/P_n improper: raise the order of Q0")
    nrz, drz = signal.bilinear(nr, dr, fs=R.FS)
    a_n = math.exp(-R.TS / tau_an)
    nw, dw = np.polymul(nqz, [1 - a_n]), np.polymul(dqz, [1.0, -a_n])
    nw, dw = np.polymul(nw, R.BUT_B), np.polymul(dw, R.BUT_A)
    ikn = R.inv_kn(v)
    return _stack([(_tf(nw, dw), 1, 1.0), (_tf(np.asarray(nrz) * ikn, drz), 0, -1.0)])
