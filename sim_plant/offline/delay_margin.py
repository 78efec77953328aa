"""Delay margin of the sampled steering loop, found on its closed-loop poles.

The delay margin is the smallest extra pure delay, anywhere between the controller's output
and the plant, that puts a closed-loop pole on the unit circle.  A delay that is not a whole
number of samples changes the sampled plant: the held command then acts partly over one sample
and partly over the next (the modified z-transform; ``discrete_loop.closed_loop`` with
``extra_delay``, placed between the actuator's held angle and the car).  That changes the loop's gain as well as its phase, most of all near the
Nyquist frequency.  So the continuous-time rule "phase margin over crossover frequency" does
not hold there.  Where the loop gain is above 1 at Nyquist (the shipped design at 5 m/s on
dry road: 1.27 with 0° phase), that rule overstates the margin: 1.48 samples against an exact
0.9.

The search scans the extra delay in steps of ``1/SCAN_PER_SAMPLE`` sample up to
``max_samples``, then bisects the first step at which the largest pole radius reaches 1.  The
pole on the circle at that delay gives the frequency; there |L| = 1, a gain crossover of the
delayed loop, which the tests check in the frequency domain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_py import model_regulator as mr
from sim_plant.car.vehicle import VehicleParams
from sim_plant.offline.discrete_loop import IDEAL, discrete_loop_matrix
from sim_plant.offline.loop_plant import LoopModels

SCAN_PER_SAMPLE = 4  # scan steps per sample of extra delay
MAX_SAMPLES = 40.0  # longest extra delay searched, in samples
TOLERANCE = 1e-5  # samples, where the bisection stops


@dataclass(frozen=True)
class DelayMargin:
    samples: float | None  # None: stable for every delay up to the searched limit
    crossover_hz: float | None  # frequency of the pole that reaches the unit circle

    def seconds(self, ts: float) -> float | None:
        return None if self.samples is None else self.samples * ts


def _critical(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
              extra: float, models: LoopModels) -> tuple[float, complex]:
    poles = np.linalg.eigvals(discrete_loop_matrix(params, coeffs, delay_steps, extra_delay=extra, models=models)[0])
    i = int(np.argmax(np.abs(poles)))
    return float(abs(poles[i])), complex(poles[i])


def delay_margin(params: VehicleParams, coeffs: mr.Coefficients, delay_steps: int,
                 max_samples: float = MAX_SAMPLES, models: LoopModels = IDEAL) -> DelayMargin:
    """The smallest extra delay (in samples) at which the loop is on the stability limit.

    0 if the loop is unstable without extra delay.
    """
    radius, pole = _critical(params, coeffs, delay_steps, 0.0, models)
    if radius >= 1.0:
        return DelayMargin(0.0, abs(math.atan2(pole.imag, pole.real)) / (2.0 * math.pi * coeffs.ts))
    step = 1.0 / SCAN_PER_SAMPLE
    lo = 0.0
    for i in range(1, int(math.ceil(max_samples * SCAN_PER_SAMPLE)) + 1):
        hi = i * step
        if _critical(params, coeffs, delay_steps, hi, models)[0] >= 1.0:
            break
        lo = hi
    else:
        return DelayMargin(None, None)
    while hi - lo > TOLERANCE:
        mid = 0.5 * (lo + hi)
        if _critical(params, coeffs, delay_steps, mid, models)[0] >= 1.0:
            hi = mid
        else:
            lo = mid
    pole = _critical(params, coeffs, delay_steps, hi, models)[1]
    return DelayMargin(hi, abs(math.atan2(pole.imag, pole.real)) / (2.0 * math.pi * coeffs.ts))
