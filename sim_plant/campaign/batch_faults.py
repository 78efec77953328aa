"""Sensor faults in a batch: ``sensor_faults.FaultedChannel.input`` vectorised for the kinds a
campaign samples, one fault per row at most, and the error each one makes.

A row's fault is its ``fault_sensor`` (``params.FAULT_CHANNELS``; ``none``: no fault),
``fault_kind`` (``params.FAULT_KINDS``: ``stuck``, ``offset``, ``gain``, ``drift``, the
``SensorFault`` kinds ``stuck``, ``bias``, ``scale``, ``drift``), ``fault_onset`` and the value
``params.fault_value`` makes of its ``fault_size``.  It acts on the channel's input, before the
sensor's noise, filter and quantisation, from the onset (``start <= t``) to the end, with the
scalar's arithmetic: ``value``, ``x + value``, ``x * value``, ``x + value (t - start)``.

``BatchSensors`` applies ``input`` to each channel; the error of a faulted reading is the
reading less that of the same sensor without the fault (``plausibility_runs.run``'s ``clean``
copy), which ``judge.detection.FaultFigures`` judges against the monitor's bound, with the
healthy sensors' offsets its check sees (``judge.bounds.check_offset``).
"""

from __future__ import annotations

import numpy as np

from sim_plant.campaign.params import FAULT_CHANNELS, FAULT_KINDS, SampleSet, fault_value


class BatchFaults:
    """The rows' sensor faults: ``input(channel, t, x)`` is x as the faulted channel's sensing
    element gives it at time t (x itself in the rows without a fault on ``channel``)."""

    def __init__(self, s: SampleSet) -> None:
        sensor = s["fault_sensor"].astype(np.int64)
        kind = s["fault_kind"].astype(np.int64)
        self.onset = s["fault_onset"]
        self.value = fault_value(sensor, kind, s["fault_size"])
        self.sensor = sensor
        #: channel -> its faulted rows (only the channels some row faults)
        self.rows = {ch: sensor == code for code, ch in enumerate(FAULT_CHANNELS)
                     if ch != "none" and bool((sensor == code).any())}
        self.kinds = {name: kind == code for code, name in enumerate(FAULT_KINDS)}

    def input(self, channel: str, t: float, x: np.ndarray) -> np.ndarray:
        rows = self.rows.get(channel)
        if rows is None:
            return x
        on = rows & (self.onset <= t)
        if not on.any():
            return x
        k, value = self.kinds, self.value
        x = np.where(on & k["stuck"], value, x)
        x = np.where(on & k["offset"], x + value, x)
        x = np.where(on & k["gain"], x * value, x)
        return np.where(on & k["drift"], x + value * (t - self.onset), x)
