"""One campaign sample as a scenario file that ``mrsteer hil run --scenario FILE`` plays on the bus.

The file carries every key of ``car.scenario``'s format the sample sets (the realistic car:
``plant``, ``[actuator]``, ``[sensors]`` with its seed, the driver model, the one event, the
sensor fault as a ``[[sensor_fault]]`` table), with
floats written as Python's ``repr`` so that they read back bit for bit.  Reading the file back
with ``scenario.load`` gives the very ``Scenario`` that ``params.scenario_for`` built, which the
scalar reference and the batch engine ran (a test holds this).
"""

from __future__ import annotations

import math

from sim_plant.car import scenario as scn
from sim_plant.car.disturbances import parameter_names
from sim_plant.car.sensors import SensorConfig


def _num(x: float) -> str:
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(float(x))


def to_toml(sc: scn.Scenario, comments: list[str] | None = None) -> str:
    """The scenario file of ``sc`` (a realistic-car scenario with one event)."""
    lines = [f"# {c}" for c in comments or []]
    lines += [f'name = "{sc.name}"', f'description = "{sc.description}"', f"duration = {_num(sc.duration)}",
              f"v = {_num(sc.v)}", f"mu = {_num(sc.mu)}", f"mass = {_num(sc.mass)}", f'plant = "{sc.plant}"', "",
              "[driver]", f'mode = "{sc.driver.mode}"', f"reaction_time = {_num(sc.driver.reaction_time)}",
              f"time_constant = {_num(sc.driver.time_constant)}", "", "[actuator]"]
    a = sc.actuator
    lines += [f"order = {a.order}", f"limit_deg = {_num(a.limit_deg)}", f"rate_limit_deg_s = {_num(a.rate_limit_deg_s)}",
              f"time_constant_s = {_num(a.time_constant_s)}", f"dead_time_samples = {a.dead_time_samples}", ""]
    s = sc.sensors
    lines += ["[sensors]", f"seed = {s.seed}", "", "[sensors.yaw_rate]",
              f"noise_density = {_num(s.yaw_rate.noise_density)}", f"bias_deg_s = {_num(s.yaw_rate.bias_deg_s)}",
              f"lowpass_hz = {_num(s.yaw_rate.lowpass_hz)}", f"quantise = {str(s.yaw_rate.quantise).lower()}", ""]
    if not s.yaw_rate_redundant_present:
        lines += ["[sensors.yaw_rate_redundant]", "present = false", ""]
    if not s.speed_redundant_present:  # a car without the second speed (a campaign's has it)
        lines += ["[sensors.speed_redundant]", "present = false", ""]
    elif s.speed_redundant != SensorConfig().speed_redundant:  # (a campaign's is the default)
        lines += ["[sensors.speed_redundant]", f"noise = {_num(s.speed_redundant.noise)}",
                  f"quantise = {str(s.speed_redundant.quantise).lower()}", ""]
    for f in sc.sensor_faults:
        lines += ["[[sensor_fault]]", f'sensor = "{f.sensor}"', f'kind = "{f.kind}"', f"start = {_num(f.start)}"]
        lines += [f"value = {_num(f.value)}"] if f.value is not None else []
        lines.append("")
    for e in sc.events:
        lines += ["[[events]]", f"t = {_num(e.t)}"]
        if e.load is None:
            lines.append(f"{e.kind} = {_num(e.value)}")
        else:
            own = [k for k in parameter_names(e.kind) if k not in ("t_start", "mass", "l_f", "l_r")]
            fields = ", ".join(f"{k} = " + (f'"{getattr(e.load, k)}"' if k == "wheel" else _num(getattr(e.load, k)))
                               for k in own)
            lines.append(f"{e.kind} = {{ {fields} }}")
        lines.append("")
    return "\n".join(lines)

