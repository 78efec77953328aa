"""Supervised child processes: a node forked from the preloaded server behaves as the same
node started as its own interpreter (exit status, stderr, stdout, environment, signals)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from sim_plant.harness.processes import RunError, spawn, spawn_preloaded, stop, wait_for_socket, wait_stderr


def test_a_preloaded_node_reports_its_usage_error_and_status(tmp_path: Path) -> None:
    p = spawn_preloaded("plant", "sim_plant.nodes.plant:main", ["--rate-hz", "-5"], tmp_path, dict(os.environ))
    assert p.popen.wait(60) == 2
    stop(p)
    assert "rate" in (tmp_path / "plant.stderr").read_text()


def test_a_preloaded_node_gets_the_environment_it_was_given(tmp_path: Path) -> None:
    # --secoc takes its key from the environment: one without a key is refused, naming it.
    env = {k: v for k, v in os.environ.items() if k != "MRSTEER_SECOC_KEY"}
    p = spawn_preloaded("controller", "firmware_py.controller.main:main", ["--secoc", "--interface", "virtual"], tmp_path, env)
    assert p.popen.wait(60) == 2
    stop(p)
    assert "MRSTEER_SECOC_KEY" in (tmp_path / "controller.stderr").read_text()


def test_a_preloaded_node_writes_stdout_to_its_file(tmp_path: Path) -> None:
    p = spawn_preloaded("bridge", "sim_plant.nodes.fault_bridge:main", ["--help"], tmp_path, dict(os.environ), stdout=True)
    assert p.popen.wait(60) == 0
    stop(p)
    assert "usage:" in (tmp_path / "bridge.stdout").read_text()


def test_a_preloaded_node_can_be_killed_and_stopped(tmp_path: Path, channel: str) -> None:
    env = dict(os.environ)
    broker = spawn_preloaded("broker", "firmware_py.platform.fallback_broker:main", ["--channel", channel], tmp_path, env)
    try:
        wait_for_socket(channel, broker)
        wait_stderr(broker, "serving")
        killed = spawn_preloaded("broker-2", "firmware_py.platform.fallback_broker:main", ["--channel", channel + "-2"], tmp_path, env)
        wait_stderr(killed, "serving")
        killed.popen.kill()
        assert killed.popen.wait(60) == -signal.SIGKILL
        stop(killed)
    finally:
        stop(broker)
    assert broker.popen.returncode == 0  # SIGTERM: its clean shutdown


def test_waiting_on_a_node_that_died_names_it(tmp_path: Path) -> None:
    p = spawn_preloaded("controller", "firmware_py.controller.main:main", ["--rate-hz", "nan"], tmp_path, dict(os.environ))
    with pytest.raises(RunError, match="controller exited with status 2"):
        wait_stderr(p, "running at", timeout=60)
    stop(p)


def test_a_plain_script_can_supervise_preloaded_nodes(tmp_path: Path) -> None:
    # No `if __name__ == "__main__"` guard: the children must not re-run the caller's script
    # (multiprocessing's spawn and forkserver methods would, and refuse to start).
    script = tmp_path / "supervise.py"
    script.write_text(
        "import os, sys\n"
        "from pathlib import Path\n"
        "from sim_plant.harness.processes import spawn_preloaded, stop\n"
        "print('script ran', flush=True)\n"
        f"p = spawn_preloaded('bridge', 'sim_plant.nodes.fault_bridge:main', ['--help'], Path({str(tmp_path)!r}),"
        " dict(os.environ), stdout=True)\n"
        "code = p.popen.wait(60)\n"
        "stop(p)\n"
        "sys.exit(code)\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("script ran") == 1
    assert "usage:" in (tmp_path / "bridge.stdout").read_text()


def test_a_bus_process_hung_at_sigterm_leaves_its_threads_stacks_before_it_is_killed(tmp_path: Path) -> None:
    # run_node's process ignores nothing, but this one's loop never looks at its stop flag.
    script = (
        "import can, time, sys\n"
        "from firmware_py.platform.lifecycle import run_node\n"
        "def hang():\n"
        "    while True:\n"
        "        time.sleep(0.01)\n"
        "bus = can.Bus(interface='virtual', channel='hung')\n"
        "sys.exit(run_node('hung node', bus, hang, lambda *a: None, ready='running'))\n")
    p = spawn("hung", [sys.executable, "-c", script], tmp_path, dict(os.environ))
    wait_stderr(p, "running", timeout=60)
    stop(p, timeout=0.3)
    assert p.popen.returncode == -signal.SIGKILL
    err = (tmp_path / "hung.stderr").read_text()
    assert "most recent call first" in err and "in hang" in err, err


@pytest.mark.parametrize("how", ["spawn", "spawn_preloaded"])
def test_a_ctrl_c_that_lands_during_a_fork_is_not_lost(tmp_path: Path, how: str) -> None:
    """CPython runs at-fork hooks (logging registers one) in Python and drops, with "Exception
    ignored", a KeyboardInterrupt raised inside one: a Ctrl-C landing there was lost and the run
    went on.  Here a hook sends SIGINT at exactly that moment; the start must raise it."""
    script = f"""
import os, signal, sys
from pathlib import Path
from sim_plant.harness import processes
signal.signal(signal.SIGINT, signal.default_int_handler)
def ctrl_c_now():
    os.kill(os.getpid(), signal.SIGINT)
    sum(range(1000))  # bytecode after the signal: Python handlers run here, inside the hook
os.register_at_fork(after_in_parent=ctrl_c_now)
work = Path({str(tmp_path)!r})
try:
    if {how!r} == "spawn":
        p = processes.spawn("node", [sys.executable, "-c", "pass"], work, dict(os.environ))
    else:
        p = processes.spawn_preloaded("node", "builtins:len", [], work, dict(os.environ))
except KeyboardInterrupt:
    print("interrupted")
    sys.exit(0)
p.popen.wait()
print("not interrupted")
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.stdout.strip() == "interrupted", proc.stderr
    assert "Exception ignored" not in proc.stderr
