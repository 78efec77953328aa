"""The batch loads: a block from the step on which every ramp has ended is the formulas' own
values (computed once and broadcast), bitwise."""

from __future__ import annotations

import numpy as np

from sim_plant.campaign import sampling, spec
from sim_plant.car.nonlinear import BatchCar
from sim_plant.campaign.loads import BLOCK, BLOWOUT, SPLIT, GripLoads, IntactLoads

CAMPAIGN = """
samples = 120
seed = 9
sampling = "random"
duration = 4.0
calibrations = ["shipped"]
[parameters]
disturbance = { choice = ["yaw_moment", "split_mu_braking", "side_wind", "blowout"] }
onset = { uniform = [0.0, 1.0] }
wind_force = { uniform = [-3000.0, 3000.0] }
blowout_wheel = { choice = ["fl", "fr", "rl", "rr"] }
"""


def test_settled_blocks_are_the_formulas_values() -> None:
    c = spec.parse(CAMPAIGN, "loads.toml")
    s = sampling.samples(c, np.arange(c.samples))
    kind = s["disturbance"]
    grip = (kind == SPLIT) | (kind == BLOWOUT)
    steps = 2001  # 4 s: every wind gust (onset + 1.6 s) and blow-out has ended well before
    t = np.arange(steps, dtype=float)[:, None] * 0.002
    for rows in (np.flatnonzero(~grip), np.flatnonzero(grip)):
        part = s.take(rows)
        make = (lambda: IntactLoads(part)) if not grip[rows[0]] else (
            lambda: GripLoads(part, BatchCar(part["v"], part["mu"], part["mass"], 0.002)))
        whole = make().block(t)  # one block from t = 0: every value computed by the formulas
        blocked, settled = make(), 0
        for k0 in range(0, steps, BLOCK):
            part_t = t[k0:k0 + BLOCK]
            got = blocked.block(part_t)
            settled += not got["m_z"].flags.writeable  # a broadcast block
            for name, value in got.items():
                if value is None:
                    assert whole[name] is None
                    continue
                expected = whole[name] if whole[name].shape[0] > 1 else np.broadcast_to(whole[name], value.shape)
                expected = expected[k0:k0 + BLOCK] if expected.shape[0] == steps else expected
                assert np.array_equal(value, expected), (name, k0)
        assert settled > steps // BLOCK // 3  # most blocks after the last ramp's end


def test_the_split_mu_rows_wheel_slip_is_the_scalar_disturbance_s() -> None:
    """``GripLoads``' ``wheel_slip`` (the second speed's braked wheels) against
    ``SplitMuBraking.wheel_slip`` of each row's stop, through the pressure ramp and after; 0 in
    the blow-out rows."""
    from sim_plant.car.disturbances import SplitMuBraking

    c = spec.parse(CAMPAIGN.replace('"yaw_moment", ', "").replace('"side_wind", ', ""), "loads.toml")
    s = sampling.samples(c, np.arange(c.samples))
    t = np.arange(700, dtype=float)[:, None] * 0.002
    slip = GripLoads(s, BatchCar(s["v"], s["mu"], s["mass"], 0.002)).block(t)["wheel_slip"]
    split = np.flatnonzero(s["disturbance"] == SPLIT)
    assert split.size > 10 and not slip[:, s["disturbance"] == BLOWOUT].any()
    abs_seen = 0
    for i in split:
        stop = SplitMuBraking(t_start=float(s["onset"][i]), mu_left=float(s["mu"][i]),
                              mu_right=float(s["mu_split"][i]), deceleration=float(s["deceleration"][i]),
                              mass=float(s["mass"][i]))
        expected = [stop.at(float(x)).wheel_slip for x in t[:, 0]]
        assert np.allclose(slip[:, i], expected, rtol=1e-12, atol=1e-15), i  # numpy's cos against math's
        abs_seen += max(expected) >= stop.abs_slip / 2
    assert abs_seen > 0  # some stop reaches ABS on a side
