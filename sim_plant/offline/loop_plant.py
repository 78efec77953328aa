"""The sampled plant the controller sees: car, actuator and yaw-rate sensor as one state space.

One owner for the plant of every loop analysis (poles, frequency response, margins, delay
margin, noise) and of ``simulate_discrete``'s linear stability verdict.  Per sample k, with
u_k the auxiliary command reaching the actuator (after the loop's queue of N samples and the
actuator's dead time):

* **actuator and car** as one continuous cascade under a zero-order hold of the command
  (``vehicle.zoh_discretize`` of the whole): the actuator's linear position response
  (T y' + y = u, or y'' + 2 zeta w_n y' + w_n^2 y = w_n^2 u, from ``ActuatorModelConfig``)
  steers the single-track car of eq. (14), so the car sees the position as it moves within
  the sample.  ``order = 0`` is the paper's G_sa = 1 (the held command steers the car).  The
  range and rate limit are nonlinear and left to the simulation; the dead time is whole samples
  of delay and joins the loop's queue (``dead_time``).  ``frac`` of a sample of further pure
  delay at the cascade's input gives the modified z-transform (the delay-margin search).
  Note: ``PositionActuator`` on its own returns the position at the *end* of a step, which a
  plant that holds it over the step sees half a sample early; the exact cascade is used here
  (and by ``simulate_discrete``), and it is the one that reproduces issue 15's figures.
* **yaw-rate sensor** (``SensorConfig``): the 2nd-order Butterworth low-pass that ``Sensors``
  uses (its coefficients taken from ``Sensors(config, ts).lowpass``), as a state space of the
  direct form II transposed; white noise n_k enters at its input (measured = LPF(r + n)).
  Bias and quantisation are left to the simulation; ``SensorConfig.ideal()`` is measured = r.

    x+ = A x + b u_k + b_prev u_{k-1} + g M_z + g_driver delta_d + e n_k,   measured_k = c x + d n_k

``b_prev`` (None without a fractional delay) carries the early part of the delayed command.
State x = [beta, r, actuator position (, rate), filter states].  With the ideal actuator and
sensors, x = [beta, r] and (A, b, b_prev) are exactly the ZOH plant of today's loop.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np

from sim_plant.car.actuator_dynamics import ActuatorModelConfig
from sim_plant.car.sensors import SensorConfig, Sensors, YawRateSensorConfig
from sim_plant.car.vehicle import VehicleParams, state_space, zoh_discretize


@dataclass(frozen=True)
class LoopModels:
    """The actuator and sensor models in the loop (``--actuator``, ``--sensors``)."""

    actuator: ActuatorModelConfig = ActuatorModelConfig.ideal()
    sensors: SensorConfig = SensorConfig.ideal()

    @classmethod
    def ideal(cls) -> "LoopModels":
        """G_sa = 1 and exact sensors: the paper's loop, today's analysis."""
        return cls()

    @classmethod
    def reference(cls) -> "LoopModels":
        """Issue 15's reference loop: first-order 20 ms actuator within +-3 deg, 30 Hz Butterworth
        on the yaw rate, BMG160 noise density (the product defaults)."""
        return cls(ActuatorModelConfig.default(), SensorConfig.default())

    @property
    def is_ideal(self) -> bool:
        return self.actuator.order == 0 and self.actuator.dead_time_samples == 0 and self.sensors.exact

    def deterministic(self) -> "LoopModels":
        """The same loop without the sensors' noise, bias and quantisation (the filter kept):
        for the step-response figures, which must not depend on a noise seed."""
        if self.sensors.exact:
            return self
        yaw = YawRateSensorConfig(noise_density=0.0, bias_deg_s=0.0,
                                  lowpass_hz=self.sensors.yaw_rate.lowpass_hz, quantise=False)
        quiet = replace(self.sensors, yaw_rate=yaw, steer=replace(self.sensors.steer, noise=0.0, quantise=False),
                        speed=replace(self.sensors.speed, noise=0.0, quantise=False))
        return replace(self, sensors=quiet)

    def with_time_constant_scaled(self, factor: float) -> "LoopModels":
        """The actuator ``factor`` times slower: T * factor (order 1), w_n / factor (order 2)."""
        a = self.actuator
        if a.order == 0:
            return self
        scaled = (replace(a, time_constant_s=a.time_constant_s * factor) if a.order == 1
                  else replace(a, natural_frequency_hz=a.natural_frequency_hz / factor))
        return replace(self, actuator=scaled)

    def yaw_noise_sigma(self, ts: float) -> float:
        """Per-sample yaw-rate noise sigma (rad/s) of the sensors at step ts (0 for exact sensors)."""
        return 0.0 if self.sensors.exact else Sensors(self.sensors, ts).yaw_sigma

    def describe(self) -> dict[str, object]:
        a, s = self.actuator, self.sensors
        act = ("ideal" if a.order == 0 else f"order {a.order}, " + (
            f"T {a.time_constant_s * 1e3:g} ms" if a.order == 1 else f"{a.natural_frequency_hz:g} Hz, zeta {a.damping:g}")
               + f", +-{a.limit_deg:g} deg, dead time {a.dead_time_samples}")
        sen = "ideal" if s.exact else (f"low-pass {s.yaw_rate.lowpass_hz:g} Hz, noise "
                                       f"{s.yaw_rate.noise_density:g} deg/s/sqrt(Hz), seed {s.seed}")
        return {"actuator": act, "sensors": sen}


@dataclass(frozen=True)
class SampledPlant:
    """x+ = a x + b u + b_prev u_prev + g M_z + e n,  measured = c x + d n,  r = x[1].

    The arrays are shared between callers (cached) and must not be written to."""

    a: np.ndarray
    b: np.ndarray
    b_prev: np.ndarray | None
    g: np.ndarray
    g_driver: np.ndarray  # a held driver's angle (it steers the car directly)
    e: np.ndarray
    c: np.ndarray
    d: float
    dead_time: int  # the actuator's dead time, whole samples ahead of it
    cascade: int  # states of the car and actuator (the filter's follow)

    @property
    def order(self) -> int:
        return self.a.shape[0]


def _cascade(params: VehicleParams, actuator: ActuatorModelConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous (A, b_command, [b_Mz, b_driver]) of the car driven by the actuator's position:
    state [beta, r(, position(, rate))]; without an actuator the command steers the car directly.
    The driver's angle steers the car directly (the actuator superimposes its own)."""
    ss = state_space(params)
    if actuator.order == 0:
        return ss.A, ss.B[:, 0], np.column_stack([ss.B[:, 1], ss.B[:, 0]])
    if actuator.order == 1:
        a_act, b_act = np.array([[-1.0 / actuator.time_constant_s]]), np.array([1.0 / actuator.time_constant_s])
    else:
        w = 2.0 * np.pi * actuator.natural_frequency_hz
        a_act, b_act = np.array([[0.0, 1.0], [-w * w, -2.0 * actuator.damping * w]]), np.array([0.0, w * w])
    n_a = a_act.shape[0]
    A = np.zeros((2 + n_a, 2 + n_a))
    A[:2, :2], A[:2, 2], A[2:, 2:] = ss.A, ss.B[:, 0], a_act
    b, g = np.zeros(2 + n_a), np.zeros((2 + n_a, 2))
    b[2:], g[:2, 0], g[:2, 1] = b_act, ss.B[:, 1], ss.B[:, 0]
    return A, b, g


def _held(params: VehicleParams, actuator: ActuatorModelConfig, ts: float, frac: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """(Phi, Gamma_late, Gamma_early or None, [Gamma_Mz, Gamma_driver]): the cascade under a
    zero-order hold with ``frac`` of a sample of pure delay at its command input (the modified
    z-transform)."""
    A, b, g = _cascade(params, actuator)
    inputs = np.column_stack([b, g])  # command, M_z, driver: one matrix exponential for all three
    phi, gamma = zoh_discretize(A, inputs, ts)
    held = gamma[:, 1:]
    if frac == 0.0:
        return phi, gamma[:, 0], None, held
    phi_late, gamma_late = zoh_discretize(A, inputs[:, :1], (1.0 - frac) * ts)
    gamma_early = phi_late @ zoh_discretize(A, inputs[:, :1], frac * ts)[1]
    return phi, gamma_late[:, 0], gamma_early[:, 0], held


def _lowpass(sensors: SensorConfig, ts: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(b, a) of the sensors' yaw-rate filter, normalised (a[0] = 1), or None without one."""
    if sensors.exact:
        return None
    return Sensors(sensors, ts).lowpass


@functools.lru_cache(maxsize=2048)
def sampled_plant(params: VehicleParams, ts: float, models: LoopModels = LoopModels(),
                  frac: float = 0.0) -> SampledPlant:
    """The augmented sampled plant at one operating point (see the module docstring).
    Cached: margin searches ask for the same few delays at one point many times."""
    phi, late, early, held = _held(params, models.actuator, ts, frac)
    filt = _lowpass(models.sensors, ts)
    n_c = phi.shape[0]
    n_s = 0 if filt is None else 2
    n = n_c + n_s
    A = np.zeros((n, n))
    A[:n_c, :n_c] = phi
    b = np.zeros(n)
    b[:n_c] = late
    b_prev = None
    if early is not None:
        b_prev = np.zeros(n)
        b_prev[:n_c] = early
    g, g_driver = np.zeros(n), np.zeros(n)
    g[:n_c], g_driver[:n_c] = held[:, 0], held[:, 1]
    e = np.zeros(n)
    c = np.zeros(n)
    if filt is None:
        c[1], d = 1.0, 1.0
    else:
        (b0, b1, b2), (_, a1, a2) = filt
        i0 = n_c
        # Direct form II transposed of LPF(r + n): y = b0 (r + n) + s0,
        # s0+ = b1 (r + n) - a1 y + s1,  s1+ = b2 (r + n) - a2 y.
        A[i0, 1], A[i0, i0], A[i0, i0 + 1] = b1 - a1 * b0, -a1, 1.0
        A[i0 + 1, 1], A[i0 + 1, i0] = b2 - a2 * b0, -a2
        e[i0], e[i0 + 1] = b1 - a1 * b0, b2 - a2 * b0
        c[1], c[i0], d = b0, 1.0, b0
    for arr in (A, b, g, g_driver, e, c) + ((b_prev,) if b_prev is not None else ()):
        arr.setflags(write=False)
    return SampledPlant(A, b, b_prev, g, g_driver, e, c, float(d), models.actuator.dead_time_samples, n_c)


def measured_response(plant: SampledPlant, z: np.ndarray | complex) -> np.ndarray:
    """Transfer function u -> measured yaw rate, c (zI - A)^-1 (b + b_prev / z), at points z."""
    z = np.asarray(z, dtype=complex)
    flat = z.reshape(-1)
    n = plant.order
    rhs = np.broadcast_to(plant.b.astype(complex), (flat.size, n)).copy()
    if plant.b_prev is not None:
        rhs += plant.b_prev[None, :] / flat[:, None]
    if n == 2:  # the 2x2 plant in closed form (today's loop, and the fast path of the tuner's screen)
        (p00, p01), (p10, p11) = plant.a
        det = (flat - p00) * (flat - p11) - p01 * p10
        x1 = ((flat - p00) * rhs[:, 1] + p10 * rhs[:, 0]) / det
        x0 = ((flat - p11) * rhs[:, 0] + p01 * rhs[:, 1]) / det
        out = plant.c[0] * x0 + plant.c[1] * x1
    else:
        mats = flat[:, None, None] * np.eye(n)[None] - plant.a[None]
        out = np.einsum("j,ij->i", plant.c, np.linalg.solve(mats, rhs[..., None])[..., 0])
    return out.reshape(z.shape)
