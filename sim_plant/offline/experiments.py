"""The experiments behind ``mrsteer sim``: yaw-moment step, driver steering step, threshold.

``ts == 0`` selects the continuous reference; ``ts > 0`` runs the firmware at that step
with ``delay_steps`` samples of loop delay (see ``closed_loop``).
"""

from __future__ import annotations

import math
from dataclasses import replace

from firmware_py import model_regulator as mr
from sim_plant.offline.closed_loop import Experiment, Trace, simulate_continuous, simulate_discrete
from sim_plant.car.plants import LINEAR
from sim_plant.car.vehicle import VehicleParams, steering_tf
from sim_plant.offline.discrete_loop import IDEAL
from sim_plant.offline.loop_plant import LoopModels


def run(exp: Experiment, ts: float = 0.0, delay_steps: int = 1, models: LoopModels = IDEAL,
        plant: str = LINEAR) -> Trace:
    """Continuous reference for ``ts == 0``, otherwise the firmware at step ``ts`` with the
    actuator and sensor ``models`` in the loop, on the ``plant`` car (``plants.PLANTS``)."""
    if ts == 0.0:
        if plant != LINEAR:
            raise ValueError(f"the {plant} car runs with the firmware at a step: give --ts > 0 (the continuous "
                             "reference, --ts 0, is of the linear car)")
        if not models.is_ideal:
            raise ValueError("an actuator or sensor model needs the sampled loop: give --ts > 0")
        return simulate_continuous(exp)
    return simulate_discrete(exp, ts, delay_steps, models, plant)


def disturbance(params: VehicleParams, m_z: float, controller: str,
                config: mr.ControllerConfig, duration: float = 3.0) -> Experiment:
    """A step of yaw moment M_z at t = 0 with the driver's wheel held straight (Figure 9)."""
    return Experiment(params, controller, _for(config, controller), m_z=m_z, duration=duration)


def steer_step_angle(params: VehicleParams) -> float:
    """Front-wheel step that gives a steady yaw rate of 1 rad/s for the uncontrolled car on
    dry road at this speed and mass: the normalisation of Figure 8."""
    return 1.0 / steering_tf(params.at(mu=1.0)).dc_gain()


def steer(params: VehicleParams, controller: str, config: mr.ControllerConfig,
          duration: float = 3.0, saturate: bool = True) -> Experiment:
    """A driver steering step normalised as in Figure 8 (yaw rate then reads in units of 1)."""
    return Experiment(params, controller, _for(config, controller),
                      delta_driver=steer_step_angle(params), duration=duration, saturate=saturate)


def saturation_threshold(params: VehicleParams, controller: str, config: mr.ControllerConfig,
                         ts: float = 0.0, delay_steps: int = 1, duration: float = 3.0) -> float:
    """Smallest yaw-moment step (Nm) that drives the auxiliary command to its limit.

    Below the limit the loop is linear in M_z (speed constant, driver's wheel held), so the
    threshold is the limit divided by the peak command per newton-metre.
    """
    if controller == "none":
        raise ValueError("the threshold needs a controller (standard or limited)")
    probe = 1.0  # Nm: far below any saturation
    trace = run(disturbance(params, probe, controller, config, duration), ts, delay_steps)
    peak_per_nm = max(abs(float(a)) for a in (trace.aux.max(), trace.aux.min())) / probe
    if peak_per_nm <= 0.0 or not math.isfinite(peak_per_nm):
        raise ValueError("the controller produced no command; no threshold exists")
    return config.aux_limit / peak_per_nm


def _for(config: mr.ControllerConfig, controller: str) -> mr.ControllerConfig:
    return replace(config, q_form=controller) if controller in (mr.Q_LIMITED, mr.Q_STANDARD) else config
