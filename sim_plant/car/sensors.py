"""Sensor models of the realistic car: what the controller measures for r, delta_driver and v.

Yaw rate, per plant step ts (fs = 1 / ts):

    measured = Q( LPF( r + bias + n_k ) ),   n_k ~ N(0, sigma^2),  sigma^2 = N^2 fs / 2

* ``noise_density`` N (deg/s/sqrt(Hz)) is a **one-sided** density: white noise of variance
  sigma^2 sampled at fs has the one-sided PSD 2 sigma^2 / fs on [0, fs/2] (what
  scipy.signal.welch returns by default), hence sigma = N sqrt(fs / 2).  Default 0.014
  deg/s/sqrt(Hz): Bosch BMG160's datasheet (research/anchors.md section 3); at 500 Hz that is
  0.22 deg/s per sample before the filter.
* ``bias_deg_s``: a constant offset.  Default 0: an ESP sensor's offset is compensated at
  standstill; the BMG160's raw zero-rate offset is +-1 deg/s, which a file can set.
* LPF: a 2nd-order Butterworth low-pass of ``lowpass_hz`` (default 30 Hz, as production
  sensors' output filters are; issue 15), designed with scipy.signal.butter at fs (bilinear
  with pre-warping, so the -3 dB point is exactly there) and started at rest on the first
  value (scipy.signal.lfilter_zi) so it adds no start-up transient.  0 = no filter.
* Q: quantisation to the DBC signal's resolution (YawRate_YawRate's scale), read from the
  contract, so offline simulations see what the bus carries.

Steering angle and speed: optional white noise (``noise_deg``, ``noise_m_s``: RMS per sample)
and quantisation to DriverSteer_Angle's and VehicleSpeed_Speed's scale.

Noise is seeded: one ``seed`` makes a numpy SeedSequence whose spawned children feed one
Generator per sensor, so runs are reproducible and the sensors' streams independent.
``SensorConfig.ideal()`` keeps today's exact sensors (output = input).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

import mrsteer_dbc
from mrsteer_dbc import names
from sim_plant.car.model_files import ModelFileError, boolean, integer, number, read_table, reject_unknown, table

#: (message, signal) of each measured quantity in the DBC.
DBC_SIGNALS = {"yaw_rate": (names.MSG_YAW, names.SIG_YAW_RATE), "steer": (names.MSG_STEER, names.SIG_STEER_ANGLE),
               "speed": (names.MSG_SPEED, names.SIG_SPEED)}
MAX_SEED = 2**63 - 1


def dbc_resolution(quantity: str) -> float:
    """The DBC scale (one LSB) of the signal carrying ``quantity`` (yaw_rate, steer, speed)."""
    message, signal = DBC_SIGNALS[quantity]
    return float(mrsteer_dbc.load().message(message).get_signal_by_name(signal).scale)


#: key: (low, high) of each number of a sensor table.
YAW_RANGES = {"noise_density": (0.0, 10.0), "bias_deg_s": (-50.0, 50.0), "lowpass_hz": (0.0, 1000.0)}
CHANNEL_RANGES = {"noise": (0.0, 5.0)}


def _checked(cls, data: dict[str, Any], ranges: dict[str, tuple[float, float]], where: str):
    """``cls`` from a table: unknown keys refused, numbers range-checked, defaults for the rest."""
    reject_unknown(data, {f.name for f in fields(cls)}, where)
    values = {k: number(data, k, getattr(cls, k), lo, hi, where) for k, (lo, hi) in ranges.items()}
    return cls(**values, quantise=boolean(data, "quantise", True, where))


@dataclass(frozen=True)
class YawRateSensorConfig:
    noise_density: float = 0.014  # deg/s/sqrt(Hz), one-sided (Bosch BMG160)
    bias_deg_s: float = 0.0
    lowpass_hz: float = 30.0  # 0 = none
    quantise: bool = True

    def __post_init__(self) -> None:
        for k, (lo, hi) in YAW_RANGES.items():
            number(vars(self), k, 0.0, lo, hi, type(self).__name__)


@dataclass(frozen=True)
class ChannelConfig:
    """Steering angle (noise in deg RMS) or speed (noise in m/s RMS)."""

    noise: float = 0.0
    quantise: bool = True

    def __post_init__(self) -> None:
        number(vars(self), "noise", 0.0, *CHANNEL_RANGES["noise"], type(self).__name__)


@dataclass(frozen=True)
class SensorConfig:
    """The sensor models' parameters (``--sensors ideal|default|FILE``); ``exact`` = ideal sensors."""

    yaw_rate: YawRateSensorConfig = field(default_factory=YawRateSensorConfig)
    steer: ChannelConfig = field(default_factory=ChannelConfig)
    speed: ChannelConfig = field(default_factory=ChannelConfig)
    seed: int = 0
    exact: bool = False

    @classmethod
    def ideal(cls) -> "SensorConfig":
        return cls(exact=True)

    @classmethod
    def default(cls) -> "SensorConfig":
        return cls()

    @classmethod
    def from_mapping(cls, data: dict[str, Any], where: str) -> "SensorConfig":
        """From a TOML table: ``seed`` and the tables [yaw_rate], [steer], [speed]."""
        reject_unknown(data, {"seed", "yaw_rate", "steer", "speed"}, where)
        yaw_cfg = _checked(YawRateSensorConfig, table(data, "yaw_rate", where), YAW_RANGES, f"{where} [yaw_rate]")
        steer, speed = (_checked(ChannelConfig, table(data, name, where), CHANNEL_RANGES, f"{where} [{name}]")
                        for name in ("steer", "speed"))
        return cls(yaw_cfg, steer, speed, integer(data, "seed", 0, 0, MAX_SEED, where))

    @classmethod
    def load(cls, spec: str) -> "SensorConfig":
        if spec == "ideal":
            return cls.ideal()
        if spec == "default":
            return cls.default()
        return cls.from_mapping(read_table(spec), spec)


def _quantiser(on: bool, quantity: str):
    step = dbc_resolution(quantity) if on else 0.0
    return (lambda x: round(x / step) * step) if step else (lambda x: x)


class Sensors:
    """The three sensors stepped once per plant step ``ts``; SI units in and out (rad, rad/s, m/s)."""

    def __init__(self, config: SensorConfig, ts: float) -> None:
        if not (math.isfinite(ts) and ts > 0.0):
            raise ModelFileError(f"sensor step ts must be positive, got {ts!r}")
        self.config, self.ts = config, ts
        fs = 1.0 / ts
        yaw = config.yaw_rate
        if yaw.lowpass_hz >= fs / 2:
            raise ModelFileError(f"yaw_rate lowpass_hz {yaw.lowpass_hz:g} must be below the Nyquist "
                                 f"frequency {fs / 2:g} Hz of the plant step")
        self.yaw_sigma = math.radians(yaw.noise_density) * math.sqrt(fs / 2.0)
        self.yaw_bias = math.radians(yaw.bias_deg_s)
        self.steer_sigma = math.radians(config.steer.noise)
        self.speed_sigma = config.speed.noise
        if yaw.lowpass_hz > 0.0 and not config.exact:  # exact sensors filter nothing
            # Imported here: scipy.signal costs the plant process half a second of start-up,
            # which every run with ideal sensors (the default) would pay for nothing.
            from scipy.signal import butter

            b, a = butter(2, yaw.lowpass_hz, fs=fs)
            self.lowpass: tuple[np.ndarray, np.ndarray] | None = (b / a[0], a / a[0])
        else:
            self.lowpass = None
        self._q_yaw = _quantiser(yaw.quantise, "yaw_rate")
        self._q_steer = _quantiser(config.steer.quantise, "steer")
        self._q_speed = _quantiser(config.speed.quantise, "speed")
        self.reset()

    def reset(self) -> None:
        """Back to the start: the same noise sequence again, the filter unstarted."""
        children = np.random.SeedSequence(self.config.seed).spawn(3)
        self._rng_yaw, self._rng_steer, self._rng_speed = (np.random.default_rng(c) for c in children)
        self._z: list[float] | None = None

    def _filter(self, x: float) -> float:
        if self.lowpass is None:
            return x
        b, a = self.lowpass
        if self._z is None:  # at rest on the first value
            from scipy.signal import lfilter_zi

            self._z = (lfilter_zi(b, a) * x).tolist()
        z = self._z
        # scipy.signal.lfilter's direct form II transposed, one sample at a time
        y = b[0] * x + z[0]
        z[0] = b[1] * x - a[1] * y + z[1]
        z[1] = b[2] * x - a[2] * y
        return float(y)

    def yaw_rate(self, r: float) -> float:
        if self.config.exact:
            return r
        noisy = r + self.yaw_bias + (self.yaw_sigma * self._rng_yaw.standard_normal() if self.yaw_sigma else 0.0)
        return self._q_yaw(self._filter(noisy))

    def steer(self, delta: float) -> float:
        if self.config.exact:
            return delta
        noise = self.steer_sigma * self._rng_steer.standard_normal() if self.steer_sigma else 0.0
        return self._q_steer(delta + noise)

    def speed(self, v: float) -> float:
        if self.config.exact:
            return v
        noise = self.speed_sigma * self._rng_speed.standard_normal() if self.speed_sigma else 0.0
        return self._q_speed(v + noise)
