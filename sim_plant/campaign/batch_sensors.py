"""The realistic car's sensors, vectorised over a batch of samples (the car and the actuator are
``sim_plant.car``'s array models).

``BatchSensors`` is ``sim_plant.car.sensors.Sensors`` for a batch of samples, repeating its
arithmetic statement for statement: the yaw rate's and the lateral acceleration's noise (each
sample's own seeded streams, drawn as the scalar draws them: ``noise``), bias, 2nd-order
Butterworth and DBC quantisation; the yaw-rate sensor's second element (the first's noise
density and filter, no bias, its own stream); the second steering channel's noise and
quantisation; the steering angle and the speed quantised (their noise is 0 in a campaign);
the second speed (``speed_redundant``: its noise, its own stream, quantised and clamped to its
DBC field as the scalar's); the sampled sensor faults on their inputs (``batch_faults``) and the
error each makes.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from sim_plant.campaign.batch_faults import BatchFaults
from sim_plant.campaign.noise import NoiseStream
from sim_plant.car.sensors import (CHANNELS, SPEED_REDUNDANT, YAW_RATE_REDUNDANT, SensorConfig, dbc_range,
                                   dbc_resolution)
from sim_plant.car.sensors import G as G_SENSOR


class _Butterworth:
    """``sensors._Lowpass`` per row: scipy's direct form II transposed, at rest on its first
    input's noise-free value."""

    def __init__(self, hz: float, fs: float) -> None:
        from scipy.signal import butter, lfilter_zi

        b, a = butter(2, hz, fs=fs)
        b, a = b / a[0], a / a[0]
        self.b, self.a = b.tolist(), a.tolist()
        self.zi = lfilter_zi(b, a).tolist()
        self._z: tuple[np.ndarray, np.ndarray] | None = None
        self._tmp: np.ndarray | None = None

    def __call__(self, x: np.ndarray, rest: np.ndarray) -> np.ndarray:
        b, a = self.b, self.a
        if self._z is None:  # at rest on the first noise-free value (lfilter_zi)
            self._z = (self.zi[0] * rest, self.zi[1] * rest)
        z0, z1 = self._z  # (updated in place: b1 x - a1 y + z1 and b2 x - a2 y)
        y = b[0] * x + z0
        tmp = self._tmp if self._tmp is not None else np.empty_like(y)
        np.multiply(b[1], x, out=z0)
        z0 -= np.multiply(a[1], y, out=tmp)
        z0 += z1
        np.multiply(b[2], x, out=z1)
        z1 -= np.multiply(a[2], y, out=tmp)
        self._tmp = tmp
        return y


def _reading(x: np.ndarray, q: float, lo: float, hi: float) -> np.ndarray:
    """A value as its frame carries it: quantised to the signal's resolution ``q`` and saturated
    at its DBC range [lo, hi] (``Sensors._measure``'s quantiser and clamp)."""
    return np.clip(np.round(x / q) * q, lo, hi)


class BatchSensors:
    """The sensors per row (``sensors.Sensors``): the yaw rate (noise density and bias per row)
    and its second element (the same noise density and filter, no bias: ``params.scenario_for``'s
    ``[yaw_rate_redundant]``), the lateral acceleration and the steering angle's second channel
    (``config``'s noise, bias, filter, each row on its own streams), the steering angle and the
    speed (quantised; their noise is 0 in a campaign), and the second speed (``config``'s noise,
    quantised and clamped).  ``at(k)`` before a step's readings: the step, for the streams."""

    def __init__(self, noise_density: np.ndarray, bias_deg_s: np.ndarray, seeds: np.ndarray, ts: float,
                 config: SensorConfig = SensorConfig(), faults: BatchFaults | None = None,
                 steps: int | None = None) -> None:
        first, second = config.yaw_rate, config.yaw_rate_redundant
        if not config.yaw_rate_redundant_present or replace(second, noise_density=first.noise_density) != replace(
                first, bias_deg_s=0.0):
            raise ValueError("BatchSensors models the yaw-rate sensor's second element as params.scenario_for "
                             "builds it (present, the first element's filter, no bias); the config has "
                             f"present={config.yaw_rate_redundant_present}, {second}")
        fs = 1.0 / ts
        self.ts, self.faults = ts, faults
        #: per row, its faulted channel's reading less the same sensor's without the fault (the
        #: last step that read it), as ``plausibility_runs.run`` measures the fault's error
        self.error = np.zeros(seeds.size)
        tracked = set(faults.rows) if faults is not None else set()
        self.tracked = tracked
        self.sigma = np.radians(noise_density) * math.sqrt(fs / 2.0)
        self.bias = np.radians(bias_deg_s)
        lat, steer2 = config.lat_accel, config.steer_redundant
        self.lat_sigma = lat.noise_density * 1e-6 * G_SENSOR * math.sqrt(fs / 2.0)  # Sensors.lat_sigma
        self.lat_bias = lat.bias_m_s2
        #: the healthy offsets by channel (``SensorConfig.biases``; the yaw rate's per row)
        self.biases = {"yaw_rate": self.bias, "lat_accel": self.lat_bias, "yaw_rate_redundant": 0.0}
        self.steer2_sigma = math.radians(steer2.noise)
        self._yaw_lpf = _Butterworth(config.yaw_rate.lowpass_hz, fs)
        self._yaw2_lpf = _Butterworth(config.yaw_rate.lowpass_hz, fs)
        self._lat_lpf = _Butterworth(lat.lowpass_hz, fs)
        # the same filters on the fault-free input, for the error of a faulted channel
        self._yaw_clean = _Butterworth(config.yaw_rate.lowpass_hz, fs) if "yaw_rate" in tracked else None
        self._yaw2_clean = _Butterworth(config.yaw_rate.lowpass_hz, fs) if "yaw_rate_redundant" in tracked else None
        self._lat_clean = _Butterworth(lat.lowpass_hz, fs) if "lat_accel" in tracked else None
        self.q_yaw, self.q_steer, self.q_speed, self.q_lat, self.q_steer2, self.q_yaw2 = (
            dbc_resolution(q) for q in ("yaw_rate", "steer", "speed", "lat_accel", "steer_redundant",
                                        YAW_RATE_REDUNDANT))
        self.q_speed2 = dbc_resolution(SPEED_REDUNDANT)
        self.speed_range, self.speed2_range = dbc_range("speed"), dbc_range(SPEED_REDUNDANT)
        # every reading saturates at its DBC range, as Sensors' (a spinning car's yaw rate reads 3)
        self.yaw_range, self.yaw2_range, self.lat_range, self.steer_range, self.steer2_range = (
            dbc_range(q) for q in ("yaw_rate", YAW_RATE_REDUNDANT, "lat_accel", "steer", "steer_redundant"))
        # Sensors.reset's children of SeedSequence(seed): one per channel, in CHANNELS' order
        # the second steering channel is read every 25 steps, unless a row faults it
        self._yaw_noise, self._lat_noise, self._steer2_noise = (
            NoiseStream(seeds, CHANNELS.index(ch), scale, steps, dense) for ch, scale, dense in (
                ("yaw_rate", self.sigma, True), ("lat_accel", self.lat_sigma, True),
                ("steer_redundant", self.steer2_sigma, "steer_redundant" in tracked)))
        # the second yaw-rate element's child follows the faults' (one in a row with a fault)
        faulted = faults.sensor != 0 if faults is not None else np.zeros(seeds.size, dtype=bool)
        self._yaw2_noise = NoiseStream(seeds, len(CHANNELS) + faulted.astype(np.int64), self.sigma, steps)
        # the second speed's is the last child (Sensors.reset: children[-1]), after the element's;
        # its reading matters only every 25 steps, unless a row faults it (its error every step)
        if not (config.speed_redundant_present and config.speed_redundant.quantise):
            raise ValueError("BatchSensors models the second speed as params.scenario_for builds it (present, "
                             f"quantised); the config has present={config.speed_redundant_present}, "
                             f"{config.speed_redundant}")
        self._speed2_noise = NoiseStream(seeds, len(CHANNELS) + faulted.astype(np.int64) + 1,
                                         config.speed_redundant.noise, steps, "speed_redundant" in tracked)
        self._k = 0

    def at(self, k: int) -> None:
        """The step of the next readings (t = k ts for the faults)."""
        self._k = k
        self._t = k * self.ts

    def _input(self, channel: str, x: np.ndarray) -> np.ndarray:
        return x if self.faults is None else self.faults.input(channel, self._t, x)

    def _error(self, channel: str, faulted: np.ndarray, clean: np.ndarray) -> None:
        assert self.faults is not None
        self.error = np.where(self.faults.rows[channel], faulted - clean, self.error)

    def yaw_rate(self, r: np.ndarray) -> np.ndarray:
        noise = self._yaw_noise.at(self._k)  # sigma times the draw
        q = self.q_yaw
        lo, hi = self.yaw_range
        rest = self._input("yaw_rate", r) + self.bias
        y = _reading(self._yaw_lpf(rest + noise, rest), q, lo, hi)
        if self._yaw_clean is not None:
            rest = r + self.bias
            self._error("yaw_rate", y, _reading(self._yaw_clean(rest + noise, rest), q, lo, hi))
        return y

    def yaw_rate_redundant(self, r: np.ndarray) -> np.ndarray:
        """The yaw-rate sensor's second element (its bias 0: ``params.scenario_for``'s)."""
        noise = self._yaw2_noise.at(self._k)
        q = self.q_yaw2
        lo, hi = self.yaw2_range
        rest = self._input("yaw_rate_redundant", r) + 0.0
        y = _reading(self._yaw2_lpf(rest + noise, rest), q, lo, hi)
        if self._yaw2_clean is not None:
            rest = r + 0.0
            self._error("yaw_rate_redundant", y, _reading(self._yaw2_clean(rest + noise, rest), q, lo, hi))
        return y

    def lat_filtered(self, a_y: np.ndarray) -> np.ndarray:
        """The lateral acceleration's filter output, unquantised: the filter runs every step,
        and ``quantised_lat`` makes the value of a step whose reading is sent."""
        noise = self._lat_noise.at(self._k)
        rest = self._input("lat_accel", a_y) + self.lat_bias
        y = self._lat_lpf(rest + noise, rest)
        if self._lat_clean is not None:
            rest = a_y + self.lat_bias
            clean = self._lat_clean(rest + noise, rest)
            self._error("lat_accel", self.quantised_lat(y), self.quantised_lat(clean))
        return y

    def quantised_lat(self, filtered: np.ndarray) -> np.ndarray:
        """The reading sent: quantised, and saturated at the signal's range."""
        return _reading(filtered, self.q_lat, *self.lat_range)

    def steer_redundant(self, delta: np.ndarray) -> np.ndarray:
        """The second steering channel (no filter: only a step whose reading is sent needs it,
        and, for its error, every step of a row that faults it)."""
        noise = self._steer2_noise.at(self._k)
        q = self.q_steer2
        lo, hi = self.steer2_range
        y = _reading(self._input("steer_redundant", delta) + 0.0 + noise, q, lo, hi)
        if "steer_redundant" in self.tracked:
            self._error("steer_redundant", y, _reading(delta + 0.0 + noise, q, lo, hi))
        return y

    def steer(self, delta: np.ndarray) -> np.ndarray:
        lo, hi = self.steer_range
        y = _reading(self._input("steer", delta), self.q_steer, lo, hi)
        if "steer" in self.tracked:
            self._error("steer", y, _reading(delta, self.q_steer, lo, hi))
        return y

    def speed(self, v: np.ndarray) -> np.ndarray:
        """The speed (its noise 0 in a campaign), quantised and clamped to its DBC field as
        ``Sensors.speed`` (a speed stuck below 0 reads 0)."""
        lo, hi = self.speed_range
        y = _reading(self._input("speed", v), self.q_speed, lo, hi)
        if "speed" in self.tracked:
            self._error("speed", y, _reading(v, self.q_speed, lo, hi))
        return y

    def speed_redundant(self, v: np.ndarray) -> np.ndarray:
        """The second speed (``Sensors.speed_redundant``): its noise, quantised to 0.3 m/s,
        clamped to its DBC field.  Its stream advances every step whether or not it is read (so
        call it only at the steps the bus sends it, or every step for a row that faults it)."""
        noise = self._speed2_noise.at(self._k)
        q, (lo, hi) = self.q_speed2, self.speed2_range
        y = _reading(self._input("speed_redundant", v) + 0.0 + noise, q, lo, hi)
        if "speed_redundant" in self.tracked:
            self._error("speed_redundant", y, _reading(v + 0.0 + noise, q, lo, hi))
        return y
