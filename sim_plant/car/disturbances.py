"""Physical disturbances of the realistic car besides the paper's yaw-moment step.

Each disturbance is a frozen dataclass with ``at(t) -> Loads``: what it does to the car at time
t (s) as an extra yaw moment M_z (Nm, about the CG, positive turning left), a lateral force at
the CG F_y (N, positive to the left), a longitudinal deceleration a_x (m/s^2, positive slows
the car), the wheels' grip (``tyres.Grip``) and the braked rear wheels' mean longitudinal slip
(``wheel_slip``: the second speed reads the non-driven wheels, v (1 - slip)).  ``sum_loads``
adds several.  Axes are ISO 8855
(x forward, y left, z up); a longitudinal force F_x at lateral position y gives M_z = -y F_x.

* ``SplitMuBraking``: a stop with the left wheels on mu_l and the right on mu_r.  Both sides
  get the same brake pressure, i.e. half the demanded deceleration's force each; ABS caps each
  side at what its road can take, mu_side m g / 2 (static load of a side: the CG is on the
  centre line).  So F_l = min(m a/2, mu_l m g/2), F_r likewise, and

      M_z = (F_l - F_r) t / 2,     a_x = (F_l + F_r) / m.

  The wheels slip as they brake: a side whose brake force is under its cap by a tyre's
  longitudinal slip stiffness, about 20 F_z per unit slip (slip = 0.05 F / F_z), a side that
  ABS caps at the slip ABS holds, 10-20 % (``abs_slip`` 0.15; ABS's pressure cycle around it is
  not modelled); ``wheel_slip`` is the mean of the two sides (the rear axle's two wheels).
  The speed does **not** stay constant: a panic stop on mu 1.0 / 0.2 decelerates at 5.9 m/s^2
  (``nonlinear.NonlinearPlant`` integrates v).  With the paper's car, t = 1.5 m and full
  braking the moment is 0.8 * 1296 * 9.81 / 2 * 0.75 = 3814 Nm, close to the paper's 4000 Nm
  "entering unilaterally icy road" step.  The wheels' grip becomes mu_l / mu_r from the start.
* ``SideWindGust``: a lateral force rising and falling as 1 - cos ramps, acting at a centre of
  pressure ``cp_ahead`` in front of the CG: F_y = F(t), M_z = cp_ahead F(t); v constant.
* ``TyreBlowout``: one wheel loses a fraction of its cornering stiffness and of its peak force
  (``tyres.WheelGrip``) over a deflation time, and its rolling resistance rises to
  f_rr F_z,wheel, a drag at that wheel's side: M_z = +-f_rr F_z,wheel t / 2 (left wheel
  positive), a_x = f_rr F_z,wheel / m (a slight deceleration).

Every default is documented beside it with its reasoning; the track width is an assumption
(the paper gives none for its mid-sized car; 1.45-1.55 m is typical of the class).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from sim_plant.car.tyres import G, INTACT, Grip, WheelGrip, static_axle_loads
from sim_plant.car.vehicle import MAX_MU, PAPER_L_F, PAPER_L_R, PAPER_MASS

#: Assumed track width of the paper's mid-sized car (m): not in the paper; typical of the class.
TRACK_WIDTH = 1.5
WHEELS = ("fl", "fr", "rl", "rr")


@dataclass(frozen=True)
class Loads:
    """What the disturbances do to the car at one instant."""

    m_z: float = 0.0
    f_y: float = 0.0
    a_x: float = 0.0
    grip: Grip = INTACT
    wheel_slip: float = 0.0  # the braked rear wheels' mean longitudinal slip (0: rolling freely)

    def __add__(self, other: "Loads") -> "Loads":
        return Loads(self.m_z + other.m_z, self.f_y + other.f_y, self.a_x + other.a_x, self.grip.then(other.grip),
                     max(self.wheel_slip, other.wheel_slip))  # a slip is no force: the larger, not the sum


NO_LOADS = Loads()


def sum_loads(disturbances, t: float) -> Loads:
    """The loads of several disturbances at time t, added (grips composed)."""
    total = NO_LOADS
    for d in disturbances:
        total = total + d.at(t)
    return total


def _in_range(obj: object, name: str, lo: float, hi: float, lo_open: bool = False) -> None:
    value = getattr(obj, name)
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (lo < value if lo_open else lo <= value) and value <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        raise ValueError(f"{type(obj).__name__}.{name} must be in {bracket}{lo:g}, {hi:g}], got {value!r}")


def _ramp(t: float, start: float, duration: float) -> float:
    """0 before ``start``, 1 after ``start + duration``, 1 - cos in between (smooth at both ends)."""
    if t <= start:
        return 0.0
    if duration <= 0.0 or t >= start + duration:
        return 1.0
    return 0.5 * (1.0 - math.cos(math.pi * (t - start) / duration))


@dataclass(frozen=True)
class SplitMuBraking:
    t_start: float = 0.5
    mu_left: float = 1.0  # dry asphalt under the left wheels (the HIL case)
    mu_right: float = 0.2  # ice or packed snow under the right wheels
    #: Demanded deceleration, m/s^2: a panic stop asks for more than any road gives, so ABS
    #: limits both sides and the moment is the largest the road allows.
    deceleration: float = 10.0
    #: Brake-pressure build-up, s: a hydraulic brake reaches full pressure in ~0.1-0.2 s.
    ramp: float = 0.15
    track_width: float = TRACK_WIDTH
    mass: float = PAPER_MASS
    #: The slip ABS holds a wheel at: the middle of the 10-20 % in which a tyre's brake force
    #: peaks and ABS controls it (a standard figure of ABS design; the cycle around it is not
    #: modelled).
    abs_slip: float = 0.15
    #: A wheel's slip per unit of brake force over load below the cap: the inverse of a tyre's
    #: longitudinal slip stiffness, about 20 F_z per unit slip for a passenger tyre (B C D of
    #: TUMFTM's sim_vehicle_dynamics tyre, 18.8; an assumption, not a measurement).
    slip_per_force: float = 0.05

    def __post_init__(self) -> None:
        _in_range(self, "t_start", 0.0, 600.0)
        _in_range(self, "mu_left", 0.0, MAX_MU, lo_open=True)
        _in_range(self, "mu_right", 0.0, MAX_MU, lo_open=True)
        _in_range(self, "deceleration", 0.0, 15.0)
        _in_range(self, "ramp", 0.0, 2.0)
        _in_range(self, "track_width", 0.5, 3.0)
        _in_range(self, "mass", 300.0, 1e4)
        _in_range(self, "abs_slip", 0.0, 0.5)
        _in_range(self, "slip_per_force", 0.0, 0.5)

    def _demand(self, t: float) -> tuple[float, float]:
        """(each side's demanded brake force, each side's static load) in N."""
        return 0.5 * self.mass * self.deceleration * _ramp(t, self.t_start, self.ramp), 0.5 * self.mass * G

    def brake_forces(self, t: float) -> tuple[float, float]:
        """(F_left, F_right) in N, each side's brake force after ABS."""
        demand, side_load = self._demand(t)
        return min(demand, self.mu_left * side_load), min(demand, self.mu_right * side_load)

    def wheel_slip(self, t: float) -> float:
        """The mean slip of the two rear wheels: ``abs_slip`` on a side ABS caps (its pressure
        asks for more than its road gives), else ``slip_per_force`` times its force over its load."""
        demand, side_load = self._demand(t)
        rolling = self.slip_per_force * demand / side_load
        left = self.abs_slip if demand > self.mu_left * side_load else rolling
        right = self.abs_slip if demand > self.mu_right * side_load else rolling
        return 0.5 * (left + right)

    def at(self, t: float) -> Loads:
        if t < self.t_start:
            return NO_LOADS
        f_l, f_r = self.brake_forces(t)
        left, right = WheelGrip(mu=self.mu_left), WheelGrip(mu=self.mu_right)
        return Loads(m_z=(f_l - f_r) * self.track_width / 2.0, a_x=(f_l + f_r) / self.mass,
                     grip=Grip(left, right, left, right), wheel_slip=self.wheel_slip(t))


@dataclass(frozen=True)
class SideWindGust:
    t_start: float = 0.5
    #: Peak side force, N, positive to the left: about a 15 m/s crosswind gust on a car at
    #: 30 m/s (relative wind 34 m/s at 27 deg; side-force coefficient ~0.9 on a 2.2 m^2
    #: frontal area: 0.5 * 1.2 * 34^2 * 2.2 * 0.9 = 1370 N).  An assumption, not a measurement.
    peak_force: float = 1500.0
    rise_time: float = 0.3  # s, 1 - cos onset: a gust front passing a 4.5 m car at 30 m/s plus build-up
    hold_time: float = 1.0  # s at the peak
    fall_time: float = 0.3  # s, 1 - cos decay
    #: Centre of pressure ahead of the CG, m: passenger cars' side force acts in front of the
    #: CG (their aerodynamic yaw moment turns the nose downwind); ~0.2 wheelbase is assumed.
    cp_ahead: float = 0.5

    def __post_init__(self) -> None:
        _in_range(self, "t_start", 0.0, 600.0)
        _in_range(self, "peak_force", -2e4, 2e4)
        _in_range(self, "rise_time", 0.0, 10.0)
        _in_range(self, "hold_time", 0.0, 600.0)
        _in_range(self, "fall_time", 0.0, 10.0)
        _in_range(self, "cp_ahead", -3.0, 3.0)

    def force(self, t: float) -> float:
        rise = _ramp(t, self.t_start, self.rise_time)
        fall = _ramp(t, self.t_start + self.rise_time + self.hold_time, self.fall_time)
        return self.peak_force * (rise - fall)

    def at(self, t: float) -> Loads:
        f = self.force(t)
        return Loads(m_z=self.cp_ahead * f, f_y=f) if f != 0.0 else NO_LOADS


@dataclass(frozen=True)
class TyreBlowout:
    t_start: float = 0.5
    wheel: str = "fl"
    #: Fractions of the wheel's cornering stiffness and peak force lost once flat.  A flat tyre
    #: runs on its folded sidewalls; blow-out models in the literature (e.g. Blythe, Day and
    #: Grimes, SAE 980221) cut its cornering stiffness by most of its value.  Assumed values.
    stiffness_loss: float = 0.8
    peak_loss: float = 0.5
    #: Rolling-resistance coefficient of the flat tyre: an inflated car tyre has 0.01-0.015; a
    #: flat one an order of magnitude more (assumption).
    rolling_resistance: float = 0.15
    deflation_time: float = 0.2  # s, the loss grows as a 1 - cos ramp over it
    track_width: float = TRACK_WIDTH
    mass: float = PAPER_MASS
    l_f: float = PAPER_L_F
    l_r: float = PAPER_L_R

    def __post_init__(self) -> None:
        if self.wheel not in WHEELS:
            raise ValueError(f"TyreBlowout.wheel must be one of {', '.join(WHEELS)}, got {self.wheel!r}")
        _in_range(self, "t_start", 0.0, 600.0)
        _in_range(self, "stiffness_loss", 0.0, 0.99)
        _in_range(self, "peak_loss", 0.0, 0.99)
        _in_range(self, "rolling_resistance", 0.0, 1.0)
        _in_range(self, "deflation_time", 0.0, 5.0)
        _in_range(self, "track_width", 0.5, 3.0)
        _in_range(self, "mass", 300.0, 1e4)
        _in_range(self, "l_f", 0.0, 5.0, lo_open=True)
        _in_range(self, "l_r", 0.0, 5.0, lo_open=True)

    @property
    def wheel_load(self) -> float:
        """The blown wheel's static load, N (half its axle's)."""
        f_zf, f_zr = static_axle_loads(self.mass, self.l_f, self.l_r)
        return 0.5 * (f_zf if self.wheel.startswith("f") else f_zr)

    def at(self, t: float) -> Loads:
        k = _ramp(t, self.t_start, self.deflation_time)
        if k == 0.0:
            return NO_LOADS
        drag = k * self.rolling_resistance * self.wheel_load
        side = 1.0 if self.wheel.endswith("l") else -1.0
        damaged = WheelGrip(stiffness=1.0 - k * self.stiffness_loss, peak=1.0 - k * self.peak_loss)
        grip = Grip(**{w: (damaged if w == self.wheel else WheelGrip()) for w in WHEELS})
        return Loads(m_z=side * drag * self.track_width / 2.0, a_x=drag / self.mass, grip=grip)


#: The disturbances by the name a scenario file may use for them.
KINDS: dict[str, type] = {"split_mu_braking": SplitMuBraking, "side_wind": SideWindGust, "blowout": TyreBlowout}


def parameter_names(kind: str) -> tuple[str, ...]:
    """The parameters a disturbance of ``kind`` takes (for a scenario loader's unknown-key check)."""
    return tuple(f.name for f in fields(KINDS[kind]))
