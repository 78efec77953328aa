"""The campaign engine steps its controllers through the C port's cycle (``sim_plant.campaign.c_cycle``,
``ports/c/mrs_cycle_batch.c``): each period's inputs of every row, recorded as the engine passes
them, replayed through the Python cycle (``firmware_py.cycle.step``, the porting reference) give
the same command, plausibility bits, reported state, law status and flags, bit for bit, at every
step.  The car is out of this comparison (``test_campaign_engine`` holds the whole closed loop to
``reference.run``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from firmware_py import authority as au
from firmware_py import cycle as cy
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl
from sim_plant.campaign import c_cycle, engine, sampling, spec
from sim_plant.campaign.params import FAULT_CHANNELS, FAULT_KINDS, KINDS
from sim_plant.campaign.reference import authority_limit

DURATION = 1.0
SPEC = """
samples = 1000
seed = 51
sampling = "random"
duration = 1.0
calibrations = ["shipped"]
[parameters]
v = { uniform = [8.0, 40.0] }
mu = { uniform = [0.15, 1.2] }
mass = { uniform = [1000.0, 2200.0] }
disturbance = { choice = ["yaw_moment", "split_mu_braking", "side_wind", "blowout"] }
onset = { uniform = [0.0, 0.5] }
yaw_moment = { uniform = [-9000.0, 9000.0] }
mu_split = { uniform = [0.05, 1.0] }
deceleration = { uniform = [0.0, 10.0] }
wind_force = { uniform = [-6000.0, 6000.0] }
blowout_wheel = { choice = ["fl", "fr", "rl", "rr"] }
actuator_tau = { uniform = [0.005, 0.06] }
actuator_rate = { uniform = [20.0, 400.0] }
noise_density = { loguniform = [0.001, 0.2] }
bias = { uniform = [-2.0, 2.0] }
reaction_time = { uniform = [0.5, 1.0] }
driver_time_constant = { uniform = [0.1, 2.0] }
fault_sensor = { choice = ["none", "yaw_rate", "lat_accel", "steer", "steer_redundant", "speed",
                           "yaw_rate_redundant", "speed_redundant"] }
fault_kind = { choice = ["stuck", "offset", "gain", "drift"] }
fault_onset = { uniform = [0.1, 0.6] }
fault_size = { uniform = [0.5, 4.0] }
"""


class _Recording(c_cycle.CycleBatch):
    """The engine's cycle, keeping every period's inputs and outputs."""

    made: list[_Recording] = []

    def __init__(self, *args: object) -> None:
        super().__init__(*args)  # type: ignore[arg-type]
        self.inputs_seen: list[np.ndarray] = []
        self.outputs_seen: list[dict[str, np.ndarray]] = []
        _Recording.made.append(self)

    def step(self, *args: np.ndarray) -> np.ndarray:
        u = super().step(*args)
        self.inputs_seen.append(self.inputs.copy())
        self.outputs_seen.append({name: a.copy() for name, a in self.out.items()})
        return u


def _replay(config: mr.ControllerConfig, inputs: np.ndarray, outputs: dict[str, np.ndarray], row: int) -> int:
    """Row ``row``'s recorded periods through ``firmware_py.cycle.step``; asserts every output
    equal; returns the OR of its plausibility bits."""
    c = cy.configure(config, pl.PlausibilityConfig(ts=config.ts), au.AuthorityConfig(ts=config.ts,
                                                                                    u_max=authority_limit(config)))
    s, ci = cy.CycleState(), cy.CycleInputs()
    x = inputs[:, :, row].tolist()
    ored = 0
    for k, values in enumerate(x):
        (ci.delta_driver, ci.yaw_rate, ci.speed, ci.lat_accel, ci.delta_driver_redundant, ci.yaw_rate_redundant,
         ci.speed_redundant, ci.monitor_driver) = values
        u = cy.step(c, s, ci)
        got = (outputs["command"][k, row], outputs["plausibility"][k, row], outputs["reported"][k, row],
               outputs["status"][k, row], outputs["monitor_flags"][k, row], outputs["authority_flags"][k, row])
        expected = (u, s.plausibility, s.reported, s.law.status, s.monitor.flags, s.authority.flags)
        assert got == expected, f"row {row}, step {k}: C {got} != Python {expected}"
        ored |= s.plausibility
    return ored


def test_the_engine_s_c_cycle_equals_the_python_cycle_bit_for_bit_over_224_rows(
        monkeypatch: pytest.MonkeyPatch) -> None:
    c = spec.parse(SPEC, "c_cycle.toml")
    s = sampling.samples(c, np.arange(224))
    # every disturbance kind with every sensor-fault channel (and none), seven rows of each pair
    s["disturbance"][:] = np.arange(224) % len(KINDS)
    s["fault_sensor"][:] = (np.arange(224) // len(KINDS)) % len(FAULT_CHANNELS)
    s["fault_kind"][:] = (np.arange(224) // (len(KINDS) * len(FAULT_CHANNELS))) % len(FAULT_KINDS)
    config = mr.ControllerConfig()
    _Recording.made = []
    monkeypatch.setattr(engine, "CycleBatch", _Recording)
    res = engine.simulate(s, config, DURATION)
    steps = engine.steps_of(DURATION, config.ts)
    assert len(_Recording.made) == 2  # the intact rows and the grip rows, each with their fault-free twins
    rows, ored = 0, []
    for batch in _Recording.made:
        inputs = np.stack(batch.inputs_seen)
        outputs = {name: np.stack([o[name] for o in batch.outputs_seen]) for name in c_cycle.OUTPUTS}
        assert inputs.shape == (steps, len(c_cycle.INPUTS), batch.n)
        for row in range(batch.n):
            ored.append(_replay(config, inputs, outputs, row))
        rows += batch.n
    assert rows == 224 + np.count_nonzero(s["fault_sensor"])  # every row and every twin replayed
    # the monitor's paths ran: faults and degraded states among the rows, clean rows too
    bits = np.array(ored)
    assert (bits & pl.PLAUS_FAULT).any() and (bits & pl.PLAUS_DEGRADED).any() and (bits == 0).any()
    assert (res["authority_steps"] > 0).any() and (res["fault_steps"] > 0).any()


def test_campaign_run_without_the_built_c_cycle_fails_in_one_line(monkeypatch: pytest.MonkeyPatch,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from mrsteer_cli import cli

    monkeypatch.setattr(c_cycle, "lib", None)
    monkeypatch.setattr(c_cycle, "_WHY", "No module named 'sim_plant.campaign._c_cycle'")
    assert cli.main(["campaign", "run", "campaigns/does-not-matter.toml"]) != 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mrsteer: campaign run: the C control cycle"), err
    with pytest.raises(c_cycle.NotBuilt):
        engine.simulate(sampling.samples(spec.parse(SPEC, "c.toml"), np.arange(2)), None, 0.01)


def test_a_build_older_than_the_port_s_sources_is_refused_in_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    from mrsteer_cli import cli

    files = c_cycle.ffi.string(c_cycle.lib.mrs_c_cycle_files()).decode().split(",")
    assert {"mrs_cycle.c", "mrs_cycle_batch.c", "mrs_monitor.h"} <= set(files)
    for name in files:
        shutil.copy(c_cycle.PORT / name, tmp_path / name)
    monkeypatch.setattr(c_cycle, "PORT", tmp_path)
    assert c_cycle.built_from_the_port()  # the installed build is the checkout's
    with (tmp_path / "mrs_monitor.c").open("a") as f:
        f.write("/* an edit since the build */\n")
    assert not c_cycle.built_from_the_port()
    assert cli.main(["campaign", "run", "campaigns/does-not-matter.toml"]) != 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "built from other sources than ports/c" in err, err
