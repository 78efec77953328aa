"""The sampled steering loop as one state matrix: plant (``loop_plant``) + queue + firmware law.

    x+ = F x + g_mz M_z + g_noise n,     u = u_row x + u_noise n

with the firmware's law unsaturated (delta_d = 0, speed constant), N samples of loop delay,
the actuator's dead time, and ``extra_delay`` samples of further pure delay between the
actuator's held angle and the car (``loop_plant``'s modified z-transform for the fraction).
State: [plant (loop_plant.SampledPlant), z, q_1 .. q_D, (p_n), (s_1, s_2)] with q_i the command
computed i samples ago, D the deepest queue slot needed (the applied one, or the firmware's
modelled delay M), p_n the nominal actuator's position (when the calibration has one) and s_1,
s_2 the nominal filter's states (when it has one).

The firmware's recursion (docs/controller.md), rho = measured / K_n(v), with the coefficient
set of the speed (``mr.law_at``):
M = 0: u = (z - g_r0 rho) / (1 - g_w0), w = u;
M >= 1: p_n = act_a p_n + act_b q_M, w = F_n(p_n) (DF2T), u = z - g_r0 rho + g_w0 w;
z+ = g_w1 w - g_r1 rho + a u.  ``tests/test_firmware.py`` holds the firmware's ``step()`` in
closed loop equal to this matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import VehicleParams
from sim_plant.offline.loop_plant import LoopModels, SampledPlant, sampled_plant

IDEAL = LoopModels.ideal()


@dataclass(frozen=True)
class ClosedLoop:
    f: np.ndarray
    g_mz: np.ndarray
    g_noise: np.ndarray  # white yaw-rate noise at the sensor's input
    u_row: np.ndarray  # the command u_k (before the actuator)
    u_noise: float
    plant: SampledPlant  # its states come first in x


def inverse_kn(coeffs: mr.Coefficients, v: float) -> float:
    """1 / K_n(v) exactly as the firmware schedules it (eq. 15 of its nominal car)."""
    return coeffs.wheelbase / v + coeffs.k_us * v


def closed_loop(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int, loop_gain: complex = 1.0,
                extra_delay: float = 0.0, models: LoopModels = IDEAL) -> ClosedLoop:
    """The loop's state matrix and its inputs and command row (see the module docstring).

    ``loop_gain`` multiplies the command on its way into the plant (a real or complex
    perturbation of the loop, for checking margins).  ``extra_delay`` (samples, >= 0, any
    real value): with k + f of it a held angle acts for the last (1 - f) T of the sample k
    samples after the nominal one and for the first f T of the next.
    """
    if not (math.isfinite(extra_delay) and extra_delay >= 0.0):
        raise ValueError(f"extra_delay must be >= 0 samples, got {extra_delay!r}")
    whole, frac = divmod(extra_delay, 1.0)
    plant = sampled_plant(params, coeffs.ts, models, frac)
    npl = plant.order
    applied_at = delay_steps + plant.dead_time + int(whole)  # the queue slot that reaches the actuator
    parts = [(applied_at, plant.b)]
    if plant.b_prev is not None:
        parts.append((applied_at + 1, plant.b_prev))
    ikn = inverse_kn(coeffs, params.v)
    law = mr.law_at(coeffs, params.v)
    m = coeffs.model_delay
    lag = m > 0 and coeffs.act_a != 0.0  # the nominal actuator's state p_n
    flt = m > 0 and (coeffs.flt_b0, coeffs.flt_b1, coeffs.flt_b2, coeffs.flt_a1, coeffs.flt_a2) != (1.0, 0.0, 0.0,
                                                                                                    0.0, 0.0)
    depth = max(parts[-1][0], m)
    iz = npl  # index of the law's state z; queue slot i at iz + i
    ip = iz + depth + 1  # then p_n (with a lag) and the filter's two states (with a filter)
    i1 = ip + int(lag)
    n = i1 + 2 * int(flt)
    rho = np.zeros(n)
    rho[:npl] = plant.c * ikn
    rho_n = plant.d * ikn
    u_row, w_row = np.zeros(n), np.zeros(n)  # u[k], and w[k] (what the law compares the yaw rate with)
    model_rows: list[tuple[int, np.ndarray]] = []  # next-state rows of the nominal model's states
    if m == 0:
        g = coeffs.inv_one_minus_g_w0
        u_row[:] = (-law.g_r0 * rho) * g  # the same rounding as the firmware's order of operations
        u_row[iz] = g
        u_n = -law.g_r0 * g * rho_n
        w_row[:], w_n = u_row, u_n
    else:
        p_row = np.zeros(n)  # p_n[k] = act_a p_n[k-1] + act_b u[k-M]
        p_row[iz + m] = coeffs.act_b if lag else 1.0
        if lag:
            p_row[ip] = coeffs.act_a
            model_rows.append((ip, p_row))
        if flt:
            w_row[:] = coeffs.flt_b0 * p_row
            w_row[i1] = 1.0
            s1 = coeffs.flt_b1 * p_row - coeffs.flt_a1 * w_row
            s1[i1 + 1] += 1.0
            model_rows += [(i1, s1), (i1 + 1, coeffs.flt_b2 * p_row - coeffs.flt_a2 * w_row)]
        else:
            w_row[:] = p_row
        u_row[:] = law.g_w0 * w_row - law.g_r0 * rho
        u_row[iz] += 1.0
        u_n = -law.g_r0 * rho_n
        w_n = 0.0
    cplx = isinstance(loop_gain, complex)
    F = np.zeros((n, n), dtype=complex if cplx else float)
    g_noise = np.zeros(n, dtype=F.dtype)
    F[:npl, :npl] = plant.a
    g_noise[:npl] = plant.e
    for slot, column in parts:
        bcol = column * loop_gain
        if slot == 0:
            F[:npl, :] += np.outer(bcol, u_row)
            g_noise[:npl] += bcol * u_n
        else:
            F[:npl, iz + slot] += bcol  # the command queued this many samples ago is applied now
    if depth > 0:
        F[iz + 1, :] = u_row  # newest queue slot gets this sample's command
        g_noise[iz + 1] = u_n
        for i in range(1, depth):
            F[iz + 1 + i, iz + i] = 1.0
    for row, values in model_rows:
        F[row, :] = values
    F[iz, :] = law.g_w1 * w_row + law.a * u_row - law.g_r1 * rho
    g_noise[iz] = law.g_w1 * w_n + law.a * u_n - law.g_r1 * rho_n
    g_mz = np.zeros(n)
    g_mz[:npl] = plant.g
    return ClosedLoop(F, g_mz, g_noise, u_row, u_n, plant)


def discrete_loop_matrix(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
                         loop_gain: complex = 1.0, extra_delay: float = 0.0,
                         models: LoopModels = IDEAL) -> tuple[np.ndarray, np.ndarray]:
    """(F, g): the sampled loop x+ = F x + g M_z (``closed_loop``)."""
    loop = closed_loop(params, coeffs, delay_steps, loop_gain, extra_delay, models)
    return loop.f, loop.g_mz


def discrete_loop_poles(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
                        loop_gain: complex = 1.0, extra_delay: float = 0.0,
                        models: LoopModels = IDEAL) -> np.ndarray:
    """Poles of the sampled loop (``closed_loop``)."""
    return np.linalg.eigvals(discrete_loop_matrix(params, coeffs, delay_steps, loop_gain, extra_delay, models)[0])


def max_pole_radius(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
                    models: LoopModels = IDEAL, extra_delay: float = 0.0) -> float:
    return float(np.max(np.abs(discrete_loop_poles(params, coeffs, delay_steps, extra_delay=extra_delay,
                                                   models=models))))
