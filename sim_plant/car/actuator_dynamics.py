"""The auxiliary steering actuator's position response: what angle it applies for a command.

The paper takes G_sa = 1 (section 4: "for easier presentation of results") and a range of
+-3 deg of wheel rotation.  This model adds, in this order, per plant step ts:

1. dead time: the command is used ``dead_time_samples`` steps late;
2. range: the command is clamped to +-``limit_deg``;
3. the linear position response, discretised exactly (zero-order hold, ``vehicle.zoh_discretize``
   on the continuous model, i.e. a matrix exponential):
   - first order  T y' + y = u            (y_k+1 = e^(-ts/T) y_k + (1 - e^(-ts/T)) u_k)
   - second order y'' + 2 zeta w_n y' + w_n^2 y = w_n^2 u;
4. rate limit: the position moves at most ``rate_limit_deg_s`` * ts per step (the motor's top
   speed; the lagging state is limited too, so it does not run ahead of the real position);
5. end stop: the position stays within +-limit (a second-order overshoot stops there).

``step(command)`` holds the command over one step and returns the position at its end, which
the plant then applies over its next step; as T -> 0 this becomes the ideal actuator, so the
model adds no delay besides its lag.  ``order = 0`` is the ideal actuator, G_sa = 1: applied =
clamped command.

**Defaults** (``ActuatorModelConfig.default()``): first order, T = 20 ms, +-3 deg, no rate limit,
no dead time: the reference loop of issue 15.  Reasoning for 20 ms: TUM's PT1 model of a whole
steering actuator (motor, rack, column) has T = 0.05-0.06 s with rates 0.5-1 rad/s
(research/anchors.md section 3); a superimposing actuator (BMW/ZF AFS's planetary gear driven by
a small motor) moves only its own few degrees and inertia, so a faster response is expected.
No citable AFS figures were found (anchors.md: a gap), so 20 ms is an assumption, and the tuner
checks it from half to twice.  The 20 ms lag alone needs 3 deg / 20 ms = 150 deg/s for a full
step, so no separate rate limit is set by default; a file can set one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from sim_plant.car.model_files import ModelFileError, integer, number, read_table, reject_unknown
from sim_plant.car.vehicle import zoh_discretize

#: key: (low, high, low excluded) for every float parameter of ``ActuatorModelConfig``.
RANGES: dict[str, tuple[float, float, bool]] = {
    "limit_deg": (0.0, 10.0, True),
    "rate_limit_deg_s": (0.0, math.inf, True),
    "time_constant_s": (0.0, 1.0, True),
    "natural_frequency_hz": (0.0, 1000.0, True),
    "damping": (0.0, 5.0, True),
}
MAX_DEAD_TIME = 50


@dataclass(frozen=True)
class ActuatorModelConfig:
    """The actuator model's parameters (``--actuator ideal|default|FILE``)."""

    order: int = 1
    limit_deg: float = 3.0
    rate_limit_deg_s: float = math.inf
    time_constant_s: float = 0.020
    natural_frequency_hz: float = 8.0  # second order only: about the 20 ms first order's bandwidth
    damping: float = 0.7  # second order only
    dead_time_samples: int = 0

    def __post_init__(self) -> None:
        self._validate(vars(self), type(self).__name__)

    @staticmethod
    def _validate(data: dict[str, Any], where: str) -> None:
        integer(data, "order", 1, 0, 2, where)
        integer(data, "dead_time_samples", 0, 0, MAX_DEAD_TIME, where)
        for key, (lo, hi, lo_open) in RANGES.items():
            number(data, key, getattr(ActuatorModelConfig, key), lo, hi, where, lo_open)

    @classmethod
    def ideal(cls) -> "ActuatorModelConfig":
        """G_sa = 1 within +-3 deg: today's plant."""
        return cls(order=0)

    @classmethod
    def default(cls) -> "ActuatorModelConfig":
        return cls()

    @classmethod
    def from_mapping(cls, data: dict[str, Any], where: str) -> "ActuatorModelConfig":
        """From a TOML table (a model file, or a scenario's [actuator] table); defaults for absent keys."""
        names = {f.name for f in fields(cls)}
        reject_unknown(data, names, where)
        cls._validate(data, where)
        return cls(**{k: (float(v) if k in RANGES else v) for k, v in data.items()})

    @classmethod
    def load(cls, spec: str) -> "ActuatorModelConfig":
        """``ideal``, ``default`` or a TOML file of the keys above."""
        if spec == "ideal":
            return cls.ideal()
        if spec == "default":
            return cls.default()
        return cls.from_mapping(read_table(spec), spec)


class PositionActuator:
    """The actuator stepped at the plant step ``ts``; angles in rad."""

    def __init__(self, config: ActuatorModelConfig, ts: float) -> None:
        if not (math.isfinite(ts) and ts > 0.0):
            raise ModelFileError(f"actuator step ts must be positive, got {ts!r}")
        self.config = config
        self.ts = ts
        self.limit = math.radians(config.limit_deg)
        self.max_move = math.radians(config.rate_limit_deg_s) * ts
        self.max_rate = math.radians(config.rate_limit_deg_s)
        if config.order == 1:
            a, b = np.array([[-1.0 / config.time_constant_s]]), np.array([[1.0 / config.time_constant_s]])
        elif config.order == 2:
            w = 2.0 * math.pi * config.natural_frequency_hz
            a, b = np.array([[0.0, 1.0], [-w * w, -2.0 * config.damping * w]]), np.array([[0.0], [w * w]])
        else:
            a = b = None
        if a is not None:
            phi, gamma = zoh_discretize(a, b, ts)
            self._phi, self._gamma = phi.tolist(), gamma[:, 0].tolist()
        # Mean of x0 + (u - x0)(1 - e^{-t/T}) over a step: u + (x0 - u) T/ts (1 - e^{-ts/T}).
        self._mean_c = (config.time_constant_s / ts * (1.0 - math.exp(-ts / config.time_constant_s))
                        if config.order == 1 else 0.5)
        self.reset()

    def reset(self) -> None:
        self._x = [0.0] * max(self.config.order, 1)  # position (and rate for order 2)
        self.mean = 0.0  # the position's mean over the last step
        self._delay = [0.0] * self.config.dead_time_samples
        self._head = 0

    @property
    def position(self) -> float:
        return self._x[0]

    def _delayed(self, command: float) -> float:
        if not self._delay:
            return command
        out = self._delay[self._head]
        self._delay[self._head] = command
        self._head = (self._head + 1) % len(self._delay)
        return out

    def step(self, command: float) -> float:
        """Hold ``command`` (rad) over one step; the applied angle at its end (rad).  ``mean``
        is then the angle's mean over the step: what a car stepped over the same interval
        gets (the end value would be half a sample early)."""
        u = min(self.limit, max(-self.limit, self._delayed(command)))
        x = self._x
        order = self.config.order
        if order == 0:
            nxt = [u]
        elif order == 1:
            nxt = [self._phi[0][0] * x[0] + self._gamma[0] * u]
        else:
            p, g = self._phi, self._gamma
            nxt = [p[0][0] * x[0] + p[0][1] * x[1] + g[0] * u, p[1][0] * x[0] + p[1][1] * x[1] + g[1] * u]
        move = nxt[0] - x[0]
        if abs(move) > self.max_move:
            nxt[0] = x[0] + math.copysign(self.max_move, move)
            if order == 2:
                nxt[1] = math.copysign(min(abs(nxt[1]), self.max_rate), nxt[1])
        exact = order == 1 and abs(move) <= self.max_move
        if abs(nxt[0]) > self.limit:
            nxt[0] = math.copysign(self.limit, nxt[0])
            exact = False
            if order == 2:
                nxt[1] = 0.0
        # What a car integrating over the step sees: exact for an unclipped first-order move,
        # the trapezoid otherwise (the position's path between the two ends is then unknown here).
        if order == 0:
            self.mean = nxt[0]
        elif exact:
            self.mean = u + (x[0] - u) * self._mean_c
        else:
            self.mean = 0.5 * (x[0] + nxt[0])
        self._x = nxt
        return nxt[0]


class BatchPositionActuator:
    """``PositionActuator`` of order 1 (no dead time) over a batch: time constant and rate
    limit per row (the campaign engine's actuators)."""

    def __init__(self, time_constant: np.ndarray, rate_limit_deg_s: np.ndarray, limit_deg: float, ts: float) -> None:
        self.limit = math.radians(limit_deg)
        self.max_move = np.radians(rate_limit_deg_s) * ts
        # vehicle.zoh_discretize's expm of [[-1/T, 1/T], [0, 0]] ts in closed form: e^(-ts/T) and
        # 1 - e^(-ts/T) (expm1, as exact as the Pade approximant; scipy's batched expm was 0.4 s
        # per 16k rows)
        self.phi = np.exp(-ts / time_constant)
        self.gamma = -np.expm1(-ts / time_constant)
        # PositionActuator's mean over a step of an unclipped first-order move: T/ts (1 - e^(-ts/T))
        self.mean_c = time_constant / ts * (1.0 - np.exp(-ts / time_constant))
        self.position = np.zeros(time_constant.size)
        self.mean = np.zeros(time_constant.size)

    def step(self, command: np.ndarray) -> np.ndarray:
        lim = self.limit
        u = np.minimum(lim, np.maximum(-lim, command))
        x = self.position
        nxt = self.phi * x + self.gamma * u
        move = nxt - x
        exact = np.abs(move) <= self.max_move
        if exact.all() and np.abs(nxt).max() <= lim:  # no row rate-limited or at its end stop
            self.mean = u + (x - u) * self.mean_c
            self.position = nxt
            return nxt
        nxt = np.where(exact, nxt, x + np.copysign(self.max_move, move))
        stopped = np.abs(nxt) > lim
        nxt = np.where(stopped, np.copysign(lim, nxt), nxt)
        # The position's mean over the step (what the car gets): exact for an unclipped move,
        # else the trapezoid, as PositionActuator.mean
        self.mean = np.where(exact & ~stopped, u + (x - u) * self.mean_c, 0.5 * (x + nxt))
        self.position = nxt
        return nxt

