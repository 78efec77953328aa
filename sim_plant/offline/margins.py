"""Stability margins of the sampled steering loop over an operating envelope.

The loop analysed is the one the product runs: the exactly (ZOH) discretised single-track
model of eq. (14), the firmware's own discretised model regulator (``firmware_py.configure``,
unsaturated), and ``delay_steps`` whole samples between the measurement and the applied
command.  It is broken at the actuator input (the auxiliary steering angle), the usual place
for margins of a single-input loop:

    L(z) = -C(z) z^-N P(z),      closed loop stable  <=>  zeros of 1 + L(z) inside |z| = 1

with P(z) the ZOH transfer function delta_f -> r and C(z) the firmware's r -> u_a law.  From the
unsaturated recursion of ``firmware_py.model_regulator`` (delta_d = 0, u_a = y):

    C(z) = -(1/K_n(v)) (g_r0 z + g_r1) / ((1 - g_w0 z^-M) z - (g_w1 z^-M + a))

where M is the command delay the firmware models (``model_delay_steps``; 0 recovers the
plain law of docs/controller.md).

Gain margin: at every phase crossover (L real and negative) the factor 1/|L| by which the loop
gain may change before -1 is reached; the one nearest 0 dB is reported (negative when a gain
*reduction* destabilises).  Phase margin: 180 deg - |arg L| at every gain crossover (|L| = 1), the angle
by which L may turn either way before it reaches -1; the smallest is reported.  Delay margin:
the smallest extra pure delay that takes the loop to the stability limit, in s and in samples,
found on the poles of the loop with that delay in it (``sim_plant.offline.delay_margin``: a
delay of a fraction of a sample changes the sampled plant's gain too, so phase margin over
crossover frequency is not the delay margin of a sampled loop).
Closed-loop pole radius comes independently from the state matrix of
``sim_plant.offline.discrete_loop``.

With ``models`` (``loop_plant.LoopModels``) P(z) is the augmented plant from the command at the
actuator's input to the *measured* yaw rate: actuator response, car and the sensor's low-pass
(and the actuator's dead time joins z^-N); the ideal models give the loop above exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import PAPER_MASS, VehicleParams
from sim_plant.offline.delay_margin import DelayMargin, delay_margin
from sim_plant.offline.discrete_loop import IDEAL, inverse_kn, max_pole_radius
from sim_plant.offline.loop_plant import LoopModels, measured_response, sampled_plant

#: Default operating envelope of ``mrsteer design margins`` (issue 5): speed, friction, mass.
DEFAULT_SPEEDS = (5.0, 50.0, 10)
DEFAULT_FRICTIONS = (0.1, 1.0, 10)
DEFAULT_MASSES = (PAPER_MASS, 1800.0, 3)

_GRID_POINTS = 3000  # frequency grid on which crossovers are bracketed before refinement
_W_MIN = 1e-3  # rad/s, lowest frequency examined


def linspace_grid(lo: float, hi: float, count: int) -> tuple[float, ...]:
    """``count`` evenly spaced values from lo to hi inclusive (one value when lo == hi)."""
    if count < 1:
        raise ValueError(f"a grid needs at least one point, got {count}")
    if count == 1 or lo == hi:
        return (float(lo),)
    return tuple(float(x) for x in np.linspace(lo, hi, count))


@dataclass(frozen=True)
class Envelope:
    """The operating points to analyse: every combination of speed, friction and mass.

    Only the mass varies with the load; the yaw inertia stays at the paper's value, as the
    paper names speed, mass and friction as the varying quantities.
    """

    speeds: tuple[float, ...] = linspace_grid(*DEFAULT_SPEEDS)
    frictions: tuple[float, ...] = linspace_grid(*DEFAULT_FRICTIONS)
    masses: tuple[float, ...] = linspace_grid(*DEFAULT_MASSES)

    def points(self, base: VehicleParams = VehicleParams()) -> list[VehicleParams]:
        return [base.at(v=v, mu=mu, mass=m) for v in self.speeds for mu in self.frictions for m in self.masses]

    def __len__(self) -> int:
        return len(self.speeds) * len(self.frictions) * len(self.masses)


#: ``--quick``: 24 points (v 5, 20, 35, 50 m/s; mu 0.1, 0.55, 1; m 1296 and 1800 kg), the default
#: envelope's corners among them: a look in seconds, not the verdict of the default envelope.
QUICK_ENVELOPE = Envelope(linspace_grid(5.0, 50.0, 4), linspace_grid(0.1, 1.0, 3), (PAPER_MASS, 1800.0))


@dataclass(frozen=True)
class Margins:
    """Margins of one operating point. ``None`` where there is no crossover (infinite margin)."""

    v: float
    mu: float
    mass: float
    max_pole_radius: float
    gain_margin_db: float | None
    gain_crossover_hz: float | None  # frequency of the reported gain margin (phase crossover)
    phase_margin_deg: float | None
    phase_crossover_hz: float | None  # frequency of the reported phase margin (gain crossover)
    # Extra delay to the stability limit (None: not computed, or stable beyond the searched limit).
    delay_margin_s: float | None
    delay_margin_samples: float | None
    delay_crossover_hz: float | None  # frequency of the pole that reaches the unit circle

    @property
    def stable(self) -> bool:
        return self.max_pole_radius < 1.0

    def as_dict(self) -> dict[str, Any]:
        return {**vars(self), "stable": self.stable}


class LoopResponse:
    """L(e^{jwT}) of one operating point, evaluated at any frequencies (rad/s).

    The plant is ``loop_plant``'s: with ``models`` the actuator and the yaw-rate filter are in
    it (ideal: the ZOH car alone), and the actuator's dead time joins the N samples of delay."""

    def __init__(self, params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
                 models: LoopModels = IDEAL) -> None:
        self.ts = coeffs.ts
        self.plant = sampled_plant(params, coeffs.ts, models)
        self.delay_steps = delay_steps + self.plant.dead_time
        self._ikn = inverse_kn(coeffs, params.v)
        self._c = coeffs
        self._v = params.v

    def plant_path(self, w: np.ndarray | float) -> np.ndarray:
        """(1/K_n(v)) z^-N P(z) at z = e^{jwT}: everything in the loop but the controller's filter."""
        return self.plant_path_z(np.exp(1j * np.asarray(w, dtype=float) * self.ts))

    def plant_path_z(self, z: np.ndarray | complex) -> np.ndarray:
        return self._ikn * measured_response(self.plant, z) * np.asarray(z) ** (-self.delay_steps)

    def at_z(self, z: np.ndarray | complex) -> np.ndarray:
        """L(z) anywhere in the z-plane."""
        return law_response(self._c, z, self._v) * self.plant_path_z(z)

    def __call__(self, w: np.ndarray | float) -> np.ndarray:
        """L(e^{jwT}) = -C z^-N P on the unit circle, w in rad/s."""
        return self.at_z(np.exp(1j * np.asarray(w, dtype=float) * self.ts))


def law_response(c: mr.Coefficients, z: np.ndarray, v: float) -> np.ndarray:
    """The firmware's rho -> -u_a filter at speed v, with the coefficient set ``mr.law_at`` gives:
    (g_r0 z + g_r1) / ((1 - g_w0 H) z - (g_w1 H + a)), where H(z) is the nominal model's answer
    to a command: z^-M, then the nominal actuator act_b / (1 - act_a z^-1), then the nominal
    filter's biquad (H = 1 for the plain law, M = 0)."""
    p = mr.law_at(c, v)
    zi = 1.0 / np.asarray(z)
    h = zi ** c.model_delay * c.act_b / (1.0 - c.act_a * zi)
    h = h * (c.flt_b0 + zi * (c.flt_b1 + zi * c.flt_b2)) / (1.0 + zi * (c.flt_a1 + zi * c.flt_a2))
    return (p.g_r0 * z + p.g_r1) / ((1.0 - p.g_w0 * h) * z - (p.g_w1 * h + p.a))


def _crossings(f, w: np.ndarray, values: np.ndarray) -> list[float]:
    """Roots of f between grid points where ``values`` changes sign (refined with brentq)."""
    from scipy.optimize import brentq  # here, so that merely building the CLI does not load it

    roots = []
    for i in np.flatnonzero(np.signbit(values[:-1]) != np.signbit(values[1:])):
        if values[i] == 0.0:
            roots.append(float(w[i]))
        else:
            roots.append(brentq(f, w[i], w[i + 1], xtol=1e-12, rtol=1e-12))
    return roots


def frequency_margins(loop: LoopResponse) -> dict[str, float | None]:
    """Gain, phase and delay margins of one loop (see the module docstring)."""
    w_nyq = math.pi / loop.ts
    w = np.concatenate([np.geomspace(_W_MIN, w_nyq, _GRID_POINTS, endpoint=False), [w_nyq]])
    L = loop(w)

    # Phase crossovers: Im L = 0 with Re L < 0.  At Nyquist L is real, so it is checked directly.
    phase_x = [x for x in _crossings(lambda x: loop(x).imag, w[:-1], L.imag[:-1]) if loop(x).real < 0.0]
    if L[-1].real < 0.0:
        phase_x.append(w_nyq)
    gm_db, gm_w = None, None
    for x in phase_x:
        db = -20.0 * math.log10(abs(loop(x)))
        if gm_db is None or abs(db) < abs(gm_db):
            gm_db, gm_w = db, x

    # Gain crossovers: |L| = 1.
    gain_x = _crossings(lambda x: math.log(abs(loop(x))), w, np.log(np.abs(L)))
    pm_deg, pm_w = None, None
    for x in gain_x:
        pm = 180.0 - abs(math.degrees(np.angle(loop(x))))  # angular distance to -1, either way round
        if pm_deg is None or pm < pm_deg:
            pm_deg, pm_w = pm, x
    return {
        "gain_margin_db": gm_db,
        "gain_crossover_hz": None if gm_w is None else gm_w / (2.0 * math.pi),
        "phase_margin_deg": pm_deg,
        "phase_crossover_hz": None if pm_w is None else pm_w / (2.0 * math.pi),
    }


def point_margins(params: VehicleParams, config: mr.ControllerConfig, delay_steps: int,
                  with_delay_margin: bool = True, models: LoopModels = IDEAL) -> Margins:
    """Margins of one operating point; the delay margin (a pole search, the costly part) only
    when asked for, else None."""
    coeffs = mr.configure(config)
    radius = max_pole_radius(params, coeffs, delay_steps, models)
    fm = frequency_margins(LoopResponse(params, coeffs, delay_steps, models))
    dm = (delay_margin(params, coeffs, delay_steps, models=models) if with_delay_margin
          else DelayMargin(None, None))
    return Margins(v=params.v, mu=params.mu, mass=params.mass, max_pole_radius=radius, **fm,
                   delay_margin_s=dm.seconds(coeffs.ts), delay_margin_samples=dm.samples,
                   delay_crossover_hz=dm.crossover_hz)


@dataclass(frozen=True)
class EnvelopeMargins:
    """Margins at every point of an envelope and the worst of each."""

    config: mr.ControllerConfig
    delay_steps: int
    points: list[Margins]

    @property
    def stable(self) -> bool:
        return all(p.stable for p in self.points)

    def worst(self) -> dict[str, Any]:
        """Worst pole radius (largest), gain, phase and delay margins (smallest), and where."""
        where: dict[str, dict[str, float]] = {}
        out: dict[str, Any] = {}

        def pick(key: str, chooser) -> None:
            finite = [p for p in self.points if getattr(p, key) is not None]
            if not finite:
                out[key] = None
                return
            p = chooser(finite, key=lambda q: getattr(q, key))
            out[key] = getattr(p, key)
            where[key] = {"v": p.v, "mu": p.mu, "mass": p.mass}

        pick("max_pole_radius", max)
        pick("gain_margin_db", min)
        pick("phase_margin_deg", min)
        pick("delay_margin_s", min)
        out["delay_margin_samples"] = None if out["delay_margin_s"] is None else out["delay_margin_s"] / self.config.ts
        out["where"] = where
        return out

    def as_dict(self) -> dict[str, Any]:
        c = self.config
        return {
            "controller": c.q_form, **mr.describe_gains(c), "ts": c.ts, "method": c.method,
            "model_delay_steps": c.model_delay_steps, "delay_steps": self.delay_steps, "stable": self.stable, "worst": self.worst(),
            "points": [p.as_dict() for p in self.points],
        }


def envelope_margins(config: mr.ControllerConfig, delay_steps: int, envelope: Envelope = Envelope(),
                     base: VehicleParams = VehicleParams(), progress=None,
                     with_delay_margin: bool = True, models: LoopModels = IDEAL) -> EnvelopeMargins:
    """``point_margins`` at every point of the envelope; ``progress(done, total)`` if given."""
    mr.configure(config)  # validate once, before the sweep
    if delay_steps < 0:
        raise ValueError(f"delay_steps must be >= 0, got {delay_steps}")
    pts = envelope.points(base)
    out = []
    for i, p in enumerate(pts):
        out.append(point_margins(p, config, delay_steps, with_delay_margin, models))
        if progress is not None:
            progress(i + 1, len(pts))
    return EnvelopeMargins(config, delay_steps, out)


def paper_config(ts: float) -> mr.ControllerConfig:
    """The paper's own tuning (K = 10, tau = 6 ms, eq. 22) at step ts, no modelled delay."""
    from sim_plant.offline.paper import PAPER_CONFIG

    return replace(PAPER_CONFIG, ts=ts)
