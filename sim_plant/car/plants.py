"""The car a run uses: the paper's linear plant or the nonlinear one, behind one interface that
takes the physical disturbances' loads (``disturbances.Loads``).

* ``linear``: ``vehicle.DiscretePlant``, the exact ZOH model of eqs. (14)/(16); it takes
  only a yaw moment, so a scenario with physical disturbances is refused for it (``scenario``)
  and here;
* ``nonlinear``: ``nonlinear.NonlinearPlant``, magic-formula tyres and the speed a state.

``Car.step_inputs`` is the one place where a step's loads meet the plant: the grip first, then
the outputs and the advance with the loads' yaw moment, lateral force and deceleration added.
"""

from __future__ import annotations

import numpy as np

from sim_plant.car.disturbances import NO_LOADS, Loads
from sim_plant.car.nonlinear import NonlinearPlant
from sim_plant.car.vehicle import DiscretePlant, VehicleParams

LINEAR, NONLINEAR = "linear", "nonlinear"
PLANTS = (LINEAR, NONLINEAR)


class Car:
    """The chosen plant stepped at ``ts``; ``x`` is [beta, r], ``v`` the current speed."""

    def __init__(self, kind: str, params: VehicleParams, ts: float) -> None:
        if kind not in PLANTS:
            raise ValueError(f"plant must be one of {', '.join(PLANTS)}, got {kind!r}")
        self.kind = kind
        self.linear = kind == LINEAR
        self.plant: DiscretePlant | NonlinearPlant = DiscretePlant(params, ts) if self.linear else NonlinearPlant(params, ts)
        self.loads = NO_LOADS

    @property
    def x(self) -> np.ndarray:
        return self.plant.x

    @property
    def v(self) -> float:
        return self.plant.params.v if self.linear else self.plant.v  # type: ignore[union-attr]

    def set_params(self, params: VehicleParams) -> None:
        """A new operating point.  The nonlinear car's speed becomes ``params.v``: the caller
        passes the integrated speed when only mu or the mass changed."""
        self.plant.set_params(params)

    def set_loads(self, loads: Loads) -> None:
        """This step's loads (held over it); the grip changes now."""
        if self.linear:
            if loads != NO_LOADS and (loads.f_y or loads.a_x or loads.grip != NO_LOADS.grip):
                raise ValueError("the linear plant takes only yaw-moment loads: use the nonlinear plant")
        else:
            self.plant.set_grip(loads.grip)  # type: ignore[union-attr]
        self.loads = loads

    def outputs(self, delta_f: float, m_z: float) -> np.ndarray:
        """[r, beta, a_y] at the current state, the inputs and this step's loads held."""
        if self.linear:
            return self.plant.outputs(delta_f, m_z + self.loads.m_z if self.loads.m_z else m_z)
        return self.plant.outputs(delta_f, m_z + self.loads.m_z, self.loads.f_y)  # type: ignore[call-arg]

    def advance(self, delta_f: float, m_z: float) -> None:
        """One step with the inputs and this step's loads held."""
        if self.linear:
            self.plant.advance(delta_f, m_z + self.loads.m_z if self.loads.m_z else m_z)
        else:
            self.plant.advance(delta_f, m_z + self.loads.m_z, self.loads.f_y, self.loads.a_x)  # type: ignore[call-arg]
