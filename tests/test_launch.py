"""Node launches: the argument lists built from typed settings mean, to each node's own parser,
exactly those settings; each node spec names a module that runs and an entry that exists."""

from __future__ import annotations

import importlib
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from firmware_py.controller.main import build_parser as controller_parser
from firmware_py import model_regulator as mr
from sim_plant.harness import launch
from sim_plant.nodes.fault_bridge import Fault
from sim_plant.nodes.plant import build_parser as plant_parser

BUS = launch.BusArgs("mrsteer", "chan-1")


def test_controller_settings_reach_the_controller_as_given(tmp_path: Path) -> None:
    cal = replace(mr.plain_law(mr.ControllerConfig(), 43.1, 0.0212, 0.02), model_delay_steps=2)
    s = launch.ControllerSettings(333.3333333333333, launch.write_calibration(tmp_path, cal), trigger="sensors",
                                  q_form="standard", rate_limit=0.6981317007977318, duration=2.5, rt_priority=50,
                                  cpu=1, stats_out=Path("/tmp/x/controller.json"), secoc=True, slow_motion=2.5)
    a = controller_parser().parse_args(list(launch.controller(BUS, s).argv))
    assert a.slow_motion == 2.5
    assert (a.interface, a.channel, a.rate_hz, a.trigger, a.controller) == ("mrsteer", "chan-1", 333.3333333333333,
                                                                            "sensors", "standard")
    assert a.calibration == cal  # the file read back is the calibration, bit for bit
    assert (a.rate_limit, a.duration) == (0.6981317007977318, 2.5)
    assert (a.rt_priority, a.cpu, a.stats_out, a.secoc) == (50, 1, Path("/tmp/x/controller.json"), True)


def test_unset_controller_settings_leave_the_nodes_defaults() -> None:
    argv = launch.controller(launch.BusArgs("socketcan"), launch.ControllerSettings(500.0)).argv
    assert argv == ("--interface", "socketcan", "--rate-hz", "500.0")
    defaults, given = controller_parser().parse_args([]), controller_parser().parse_args(list(argv))
    assert {k: v for k, v in vars(given).items() if k not in ("interface", "rate_hz")} == \
           {k: v for k, v in vars(defaults).items() if k not in ("interface", "rate_hz")}


def test_plant_settings_reach_the_plant_as_given() -> None:
    s = launch.PlantSettings(200.0, "lockstep", "handover", duration=3.25, delay_steps=2, actuator_rate=1.0471975511965976,
                             cmd_timeout=0.02, v=27.5, mu=0.3, mz=-4000.0, no_controller=True,
                             trace_out=Path("w/plant_trace.csv"), stats_out=Path("w/plant.json"), secoc=True,
                             slow_motion=3.0)
    a = plant_parser().parse_args(list(launch.plant(BUS, s).argv))
    assert a.slow_motion == 3.0
    assert (a.channel, a.rate_hz, a.mode, a.scenario, a.duration, a.delay_steps) == ("chan-1", 200.0, "lockstep",
                                                                                       "handover", 3.25, 2)
    assert (a.actuator_rate, a.cmd_timeout, a.v, a.mu, a.mz) == (1.0471975511965976, 0.02, 27.5, 0.3, -4000.0)
    assert (a.no_controller, a.trace_out, a.stats_out, a.secoc) == (True, Path("w/plant_trace.csv"),
                                                                    Path("w/plant.json"), True)


def test_the_car_settings_reach_the_plant_as_given_and_unset_leave_the_scenarios() -> None:
    s = launch.PlantSettings(500.0, "lockstep", "split-mu", plant="nonlinear", actuator="act.toml", sensors="ideal",
                             seed=12345678901)
    a = plant_parser().parse_args(list(launch.plant(BUS, s).argv))
    assert (a.plant, a.actuator, a.sensors, a.seed) == ("nonlinear", "act.toml", "ideal", 12345678901)
    a = plant_parser().parse_args(list(launch.plant(BUS, launch.PlantSettings(500.0, "lockstep")).argv))
    assert (a.plant, a.actuator, a.sensors, a.seed) == (None, None, None, None)


def test_the_bridge_gets_its_fault_whole() -> None:
    fault = Fault("replay", "MRS_YawRate", 1.5, 2.25, 13.0)
    argv = launch.bridge("mrsteer", "veh", "ctl", fault, Path("bridge.json")).argv
    import json

    assert argv[argv.index("--fault") + 1] and Fault(**json.loads(argv[argv.index("--fault") + 1])) == fault
    assert argv[argv.index("--vehicle") + 1] == "veh" and argv[argv.index("--controller") + 1] == "ctl"


def _options(help_text: str) -> str:
    return help_text.split("options:", 1)[1]  # the usage line names the program, which differs


@pytest.mark.parametrize("spec", [launch.BROKER, launch.LOGGER, launch.CONTROLLER, launch.PLANT, launch.BRIDGE])
def test_every_node_spec_names_one_node_both_ways(spec: launch.NodeSpec, monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    # `python -m module` (a fresh interpreter) and `module:function` (a forked child) are the same node.
    monkeypatch.setenv("COLUMNS", "100")
    proc = subprocess.run(launch.Launch(spec, ("--help",)).command(), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "usage:" in proc.stdout
    module, _, func = spec.entry.partition(":")
    with pytest.raises(SystemExit) as done:
        getattr(importlib.import_module(module), func)(["--help"])
    assert done.value.code == 0
    assert _options(capsys.readouterr().out) == _options(proc.stdout)


def test_an_external_controller_gets_the_controllers_arguments_after_its_command(tmp_path: Path) -> None:
    program = launch.controller_program("python", "my-ecu --log 'a b.txt'")
    assert program == ("my-ecu", "--log", "a b.txt")  # split as a shell would
    s = launch.ControllerSettings(500.0, trigger="sensors", program=program)
    assert launch.controller(BUS, s).command() == [*program, "--interface", "mrsteer", "--channel", "chan-1",
                                                   "--rate-hz", "500.0", "--trigger", "sensors"]
    assert launch.controller_program("python") is None
    with pytest.raises(launch.LaunchError, match="empty"):
        launch.controller_program("python", "  ")
    # An external program is executed even where the Python nodes are forked (preload).
    p = launch.start("echo", launch.Launch(launch.CONTROLLER, ("hello",), ("/bin/echo",)), tmp_path, {}, stdout=True,
                     preload=True)
    assert p.popen.wait(10) == 0 and p.popen.stdout.read() == b"hello\n"
    p.popen.stdout.close()
    p.stderr.close()


def test_the_c_node_builds_from_a_read_only_tree_where_it_is_up_to_date() -> None:
    """The real-SocketCAN VM shares the tree read-only and builds nothing (the host did): asking for
    the C node there must take no lock or file inside the tree.  Run in a private mount namespace
    where ``ports/c`` is bound read-only, as the guest sees it."""
    launch.build_c_node()  # up to date on the host first, as tools/vcan-vm-test leaves it
    port = str(launch.PORT_DIR)
    probe = ("from sim_plant.harness import launch; "
             "print(launch.build_c_node())")
    script = (f"mount --bind {port} {port} && mount -o remount,bind,ro {port} || exit 77; "
              f"{sys.executable} -c '{probe}'")
    proc = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, timeout=120,
                          cwd=launch.PORT_DIR.parents[1])
    if proc.returncode == 77 or "unshare failed" in proc.stderr:
        pytest.skip(f"no private mount namespace here: {proc.stderr.strip()[-200:]}")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == str(launch.C_NODE)
