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
  value without its noise (scipy.signal.lfilter_zi) so it adds no start-up transient.  0 = no
  filter.
* Q: quantisation to the DBC signal's resolution (YawRate_YawRate's scale), read from the
  contract, so offline simulations see what the bus carries; and, as every channel's, the
  reading saturates at the signal's DBC range (+-3 rad/s: a spinning car reads 3), as the plant
  node sends it.

The yaw-rate sensor's second sensing element (``yaw_rate_redundant``, YawRate_YawRate2 in the same
frame, for the plausibility monitor's yaw-rate pair check) is the same chain with its own
parameters (a ``[yaw_rate_redundant]`` table; by default the first element's noise, filter and
quantisation, and no bias), its own noise stream and its own faults.  ``present = false`` in
that table models a sensor without it: it reads NaN, which the frame carries as SNA.

The second speed (``speed_redundant``, RedundantSensors_Speed2: on a car the non-driven wheels'
speeds, for the monitor's speed pair check) is a channel as the speed is: white noise
(``noise``, default 0.02 m/s RMS) and quantisation to its signal's 0.3 m/s, its own noise
stream (after the yaw rate's second element's) and its own faults; ``present = false`` in its
``[speed_redundant]`` table models a car without it (NaN, SNA).

Lateral acceleration (``MRS_RedundantSensors``, for the plausibility monitor): the true
a_y = v (beta' + r) of the plant through the same chain as the yaw rate, with ``noise_density``
in micro-g/sqrt(Hz) (default 180: Bosch BMI160's accelerometer, datasheet BST-BMI160-DS000-07,
Table 1, "output noise density"; 1 g = 9.80665 m/s^2), ``bias_m_s2`` and the same 30 Hz filter,
quantised to RedundantSensors_LatAccel's scale.

Steering angle and speed: optional white noise (``noise``: RMS per sample, deg and m/s)
and quantisation to DriverSteer_Angle's and VehicleSpeed_Speed's scale.  The steering-angle
sensor's second channel (``steer_redundant``) is its own channel: by default 0.01 deg RMS of
front-wheel angle (0.16 deg at the steering wheel, about one LSB of a production sensor's
0.1 deg resolution), quantised to RedundantSensors_SteerAngle's scale.

Sensor faults (``sensor_faults``; the ``faults`` of a SensorConfig, a scenario's
``[[sensor_fault]]`` tables) act on a channel's input, before its noise, filter and
quantisation, except ``frozen``, which holds the channel's output; ``Sensors.at(t)`` tells the
sensors the time before a step's readings.

Noise is seeded: one ``seed`` makes a numpy SeedSequence whose spawned children feed one
Generator per sensor (yaw rate, steer, speed, lateral acceleration, second steering channel, then
one per noise fault, then the yaw rate's second element, then the second speed: the first three streams are those of the
three-sensor model before, and each model since added its stream after the others), so runs are
reproducible and the sensors' streams independent.
``SensorConfig.ideal()`` keeps today's exact sensors (output = input, within the signal's range).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

import mrsteer_dbc
from mrsteer_dbc import names
from sim_plant.car.model_files import ModelFileError, boolean, integer, number, read_table, reject_unknown, table
from sim_plant.car.sensor_faults import MAX_TIME, FaultedChannel, SensorFault

G = 9.80665  # m/s^2 per g

#: (message, signal) of each measured quantity in the DBC.
DBC_SIGNALS = {"yaw_rate": (names.MSG_YAW, names.SIG_YAW_RATE), "steer": (names.MSG_STEER, names.SIG_STEER_ANGLE),
               "speed": (names.MSG_SPEED, names.SIG_SPEED),
               "lat_accel": (names.MSG_REDUNDANT, names.SIG_LAT_ACCEL),
               "steer_redundant": (names.MSG_REDUNDANT, names.SIG_STEER_ANGLE_2),
               "yaw_rate_redundant": (names.MSG_YAW, names.SIG_YAW_RATE_2),
               "speed_redundant": (names.MSG_REDUNDANT, names.SIG_SPEED_2)}
MAX_SEED = 2**63 - 1


def dbc_range(quantity: str) -> tuple[float, float]:
    """The DBC range [min, max] of the signal carrying ``quantity`` (a key of DBC_SIGNALS)."""
    message, signal = DBC_SIGNALS[quantity]
    return mrsteer_dbc.load().signal_range(message, signal)


def dbc_resolution(quantity: str) -> float:
    """The DBC scale (one LSB) of the signal carrying ``quantity`` (a key of DBC_SIGNALS)."""
    message, signal = DBC_SIGNALS[quantity]
    return float(mrsteer_dbc.load().message(message).get_signal_by_name(signal).scale)


#: key: (low, high) of each number of a sensor table.
YAW_RANGES = {"noise_density": (0.0, 10.0), "bias_deg_s": (-50.0, 50.0), "lowpass_hz": (0.0, 1000.0)}
LAT_RANGES = {"noise_density": (0.0, 100000.0), "bias_m_s2": (-5.0, 5.0), "lowpass_hz": (0.0, 1000.0)}
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
class LatAccelSensorConfig:
    noise_density: float = 180.0  # micro-g/sqrt(Hz), one-sided (Bosch BMI160 accelerometer)
    bias_m_s2: float = 0.0
    lowpass_hz: float = 30.0  # 0 = none
    quantise: bool = True

    def __post_init__(self) -> None:
        for k, (lo, hi) in LAT_RANGES.items():
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
    lat_accel: LatAccelSensorConfig = field(default_factory=LatAccelSensorConfig)
    steer_redundant: ChannelConfig = field(default_factory=lambda: ChannelConfig(noise=0.01))
    faults: tuple[SensorFault, ...] = ()
    yaw_rate_redundant: YawRateSensorConfig = field(default_factory=YawRateSensorConfig)
    yaw_rate_redundant_present: bool = True  # False: the sensor has no second element (NaN, SNA)
    speed_redundant: ChannelConfig = field(default_factory=lambda: ChannelConfig(noise=0.02))
    speed_redundant_present: bool = True  # False: the car has no second speed (NaN, SNA)

    @classmethod
    def ideal(cls) -> "SensorConfig":
        return cls(exact=True)

    def biases(self) -> dict[str, float]:
        """The constant offsets the healthy sensors add (rad/s, m/s^2, by channel; 0 on exact
        sensors): the yaw rate's, its second element's and the lateral acceleration's."""
        if self.exact:
            return {"yaw_rate": 0.0, "lat_accel": 0.0, YAW_RATE_REDUNDANT: 0.0}
        return {"yaw_rate": math.radians(self.yaw_rate.bias_deg_s), "lat_accel": self.lat_accel.bias_m_s2,
                YAW_RATE_REDUNDANT: math.radians(self.yaw_rate_redundant.bias_deg_s)}

    @classmethod
    def default(cls) -> "SensorConfig":
        return cls()

    @classmethod
    def from_mapping(cls, data: dict[str, Any], where: str) -> "SensorConfig":
        """From a TOML table: ``seed`` and the tables [yaw_rate], [steer], [speed], [lat_accel],
        [steer_redundant], [yaw_rate_redundant] (the yaw-rate sensor's second element: the keys
        it leaves out are [yaw_rate]'s but its bias, and ``present = false`` leaves it out),
        [speed_redundant] (the second speed: ``noise``, ``quantise``, ``present``)."""
        reject_unknown(data, {"seed", "yaw_rate", "steer", "speed", "lat_accel", "steer_redundant",
                              "yaw_rate_redundant", "speed_redundant"}, where)
        first = table(data, "yaw_rate", where)
        yaw_cfg = _checked(YawRateSensorConfig, first, YAW_RANGES, f"{where} [yaw_rate]")
        second_yaw = dict(table(data, "yaw_rate_redundant", where))
        present = boolean(second_yaw, "present", True, f"{where} [yaw_rate_redundant]")
        second_yaw.pop("present", None)
        inherited = {k: v for k, v in first.items() if k != "bias_deg_s"}  # an offset is the element's own
        yaw2_cfg = _checked(YawRateSensorConfig, {**inherited, **second_yaw}, YAW_RANGES,
                            f"{where} [yaw_rate_redundant]")
        lat_cfg = _checked(LatAccelSensorConfig, table(data, "lat_accel", where), LAT_RANGES, f"{where} [lat_accel]")
        steer, speed = (_checked(ChannelConfig, table(data, name, where), CHANNEL_RANGES, f"{where} [{name}]")
                        for name in ("steer", "speed"))
        second = table(data, "steer_redundant", where)
        steer2 = _checked(ChannelConfig, {"noise": 0.01, **second}, CHANNEL_RANGES, f"{where} [steer_redundant]")
        second_speed = dict(table(data, "speed_redundant", where))
        speed2_present = boolean(second_speed, "present", True, f"{where} [speed_redundant]")
        second_speed.pop("present", None)
        speed2 = _checked(ChannelConfig, {"noise": 0.02, **second_speed}, CHANNEL_RANGES,
                          f"{where} [speed_redundant]")
        return cls(yaw_cfg, steer, speed, integer(data, "seed", 0, 0, MAX_SEED, where), lat_accel=lat_cfg,
                   steer_redundant=steer2, yaw_rate_redundant=yaw2_cfg, yaw_rate_redundant_present=present,
                   speed_redundant=speed2, speed_redundant_present=speed2_present)

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


class _Lowpass:
    """scipy.signal.lfilter's direct form II transposed, one sample at a time, started at rest
    (lfilter_zi) on its first input's noise-free value ``rest`` (default: the input itself), so
    that it adds no start-up transient: a filter at rest on a noisy first sample carries that
    sample's whole unfiltered noise for its first ~10 ms (at 30 Hz), about 3x the filtered
    noise's sigma, which the yaw-rate pair check of two such elements read as a fault."""

    def __init__(self, hz: float, fs: float) -> None:
        # Imported here: scipy.signal costs the plant process half a second of start-up,
        # which every run with ideal sensors (the default) would pay for nothing.
        from scipy.signal import butter

        b, a = butter(2, hz, fs=fs)
        self.ba: tuple[np.ndarray, np.ndarray] = (b / a[0], a / a[0])
        self.z: list[float] | None = None

    def __call__(self, x: float, rest: float | None = None) -> float:
        b, a = self.ba
        if self.z is None:
            from scipy.signal import lfilter_zi

            self.z = (lfilter_zi(b, a) * (x if rest is None else rest)).tolist()
        z = self.z
        y = b[0] * x + z[0]
        z[0] = b[1] * x - a[1] * y + z[1]
        z[1] = b[2] * x - a[2] * y
        return float(y)


#: The channels in the order of their noise streams (the faults' streams follow them).
CHANNELS = ("yaw_rate", "steer", "speed", "lat_accel", "steer_redundant")
#: The yaw-rate sensor's second element: its stream comes after the faults' streams, so every
#: seed gives the other channels the noise it gave them before the element existed.
YAW_RATE_REDUNDANT = "yaw_rate_redundant"
#: The second speed: its stream after the yaw rate's second element's, for the same reason.
SPEED_REDUNDANT = "speed_redundant"
ALL_CHANNELS = (*CHANNELS, YAW_RATE_REDUNDANT, SPEED_REDUNDANT)


def dormant_faults(config: SensorConfig) -> SensorConfig:
    """``config`` with its faults never starting: readings as without them, from the same noise
    streams (each fault keeps its place among the seed's children, and a fault draws from its
    own stream only while active), so a faulted reading less this one's is the fault's own error."""
    return replace(config, faults=tuple(replace(f, start=MAX_TIME, stop=math.inf) for f in config.faults))


class Sensors:
    """The seven sensors stepped once per plant step ``ts``; SI units in and out (rad, rad/s,
    m/s, m/s^2).  ``at(t)`` before a step's readings sets the time the faults see."""

    def __init__(self, config: SensorConfig, ts: float) -> None:
        if not (math.isfinite(ts) and ts > 0.0):
            raise ModelFileError(f"sensor step ts must be positive, got {ts!r}")
        self.config, self.ts = config, ts
        fs = 1.0 / ts
        yaw, lat, yaw2 = config.yaw_rate, config.lat_accel, config.yaw_rate_redundant
        for name, hz in (("yaw_rate", yaw.lowpass_hz), ("lat_accel", lat.lowpass_hz),
                         (YAW_RATE_REDUNDANT, yaw2.lowpass_hz)):
            if hz >= fs / 2:
                raise ModelFileError(f"{name} lowpass_hz {hz:g} must be below the Nyquist "
                                     f"frequency {fs / 2:g} Hz of the plant step")
        self.yaw_sigma = math.radians(yaw.noise_density) * math.sqrt(fs / 2.0)
        self.lat_sigma = lat.noise_density * 1e-6 * G * math.sqrt(fs / 2.0)
        self.sigma = {"yaw_rate": self.yaw_sigma, "steer": math.radians(config.steer.noise),
                      "speed": config.speed.noise, "lat_accel": self.lat_sigma,
                      "steer_redundant": math.radians(config.steer_redundant.noise),
                      YAW_RATE_REDUNDANT: math.radians(yaw2.noise_density) * math.sqrt(fs / 2.0),
                      SPEED_REDUNDANT: config.speed_redundant.noise}
        self.bias = config.biases()  # applied only when not exact
        self._hz = {"yaw_rate": yaw.lowpass_hz, "lat_accel": lat.lowpass_hz, YAW_RATE_REDUNDANT: yaw2.lowpass_hz}
        filtered = not config.exact  # exact sensors filter nothing
        self.lowpass = _Lowpass(yaw.lowpass_hz, fs).ba if filtered and yaw.lowpass_hz > 0.0 else None
        self._q = {name: _quantiser(getattr(config, name).quantise, name) for name in ALL_CHANNELS}
        # A sensor reads nothing beyond what its signal carries, as the plant node sends it: a
        # spinning car's yaw rate reads 3 rad/s, a speed no negative value (a fault's negative
        # offset at low speed) and the second speed nothing past its 8 bits' 75 m/s.
        self._range = {name: dbc_range(name) for name in ALL_CHANNELS}
        for f in config.faults:
            if f.sensor not in ALL_CHANNELS:
                raise ModelFileError(f"sensor fault: sensor must be one of {', '.join(ALL_CHANNELS)}, "
                                     f"got {f.sensor!r}")
        self.reset()

    def reset(self) -> None:
        """Back to the start: the same noise sequence again, the filters unstarted, the faults
        not yet begun."""
        n_fault = len(self.config.faults)
        children = np.random.SeedSequence(self.config.seed).spawn(len(CHANNELS) + n_fault + 2)
        self._rng = {name: np.random.default_rng(c) for name, c in zip(CHANNELS, children)}
        self._rng[YAW_RATE_REDUNDANT] = np.random.default_rng(children[-2])
        self._rng[SPEED_REDUNDANT] = np.random.default_rng(children[-1])
        fs = 1.0 / self.ts
        self._lpf = {name: _Lowpass(hz, fs) for name, hz in self._hz.items() if hz > 0.0 and not self.config.exact}
        self._faults = {name: FaultedChannel(tuple(f for f in self.config.faults if f.sensor == name),
                                             [np.random.default_rng(children[len(CHANNELS) + i])
                                              for i, f in enumerate(self.config.faults) if f.sensor == name])
                        for name in ALL_CHANNELS}
        self.t = 0.0

    def at(self, t: float) -> None:
        """The time of the next readings (s since the start of the run), for the faults."""
        self.t = t

    def _measure(self, name: str, x: float) -> float:
        fault = self._faults[name]
        x = fault.input(self.t, x)
        if not self.config.exact:
            sigma = self.sigma[name]
            clean = x + self.bias.get(name, 0.0)
            x = clean + (sigma * self._rng[name].standard_normal() if sigma else 0.0)
            lpf = self._lpf.get(name)
            x = self._q[name](lpf(x, clean) if lpf is not None else x)
        lo, hi = self._range[name]
        return min(max(fault.output(self.t, x), lo), hi)

    def yaw_rate(self, r: float) -> float:
        return self._measure("yaw_rate", r)

    def steer(self, delta: float) -> float:
        return self._measure("steer", delta)

    def speed(self, v: float) -> float:
        return self._measure("speed", v)

    def lat_accel(self, a_y: float) -> float:
        return self._measure("lat_accel", a_y)

    def steer_redundant(self, delta: float) -> float:
        return self._measure("steer_redundant", delta)

    def yaw_rate_redundant(self, r: float) -> float:
        """The second element's reading; NaN for a sensor without one."""
        return self._measure(YAW_RATE_REDUNDANT, r) if self.config.yaw_rate_redundant_present else math.nan

    def speed_redundant(self, v: float) -> float:
        """The second speed's reading; NaN for a car without one."""
        if not self.config.speed_redundant_present:
            return math.nan
        return self._measure(SPEED_REDUNDANT, v)
