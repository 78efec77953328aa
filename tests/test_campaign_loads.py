"""The batch loads: a block from the step on which every ramp has ended is the formulas' own
values (computed once and broadcast), bitwise."""

from __future__ import annotations

import numpy as np

from sim_plant.campaign import sampling, spec
from sim_plant.campaign.batch_car import BatchCar
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
