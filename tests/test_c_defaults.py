"""The C port's default calibrations come from the Python ones: ports/c/mrs_defaults.h is what
ports/c/gen_defaults.py writes from firmware_py, the C default functions take every value from
it, and what they fill is the Python defaults bit for bit."""

from __future__ import annotations

import dataclasses
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from firmware_py import calibration

ROOT = Path(__file__).resolve().parents[1]
PORT = ROOT / "ports" / "c"
HEADER = PORT / "mrs_defaults.h"
GENERATOR = PORT / "gen_defaults.py"
CC = shutil.which("gcc")


def _generate(out: Path) -> str:
    proc = subprocess.run([sys.executable, str(GENERATOR), str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out.read_text()


def test_the_committed_header_is_what_the_generator_writes_from_the_python(tmp_path: Path) -> None:
    assert HEADER.read_text() == _generate(tmp_path / "mrs_defaults.h"), (
        "ports/c/mrs_defaults.h is stale: run python ports/c/gen_defaults.py")


def test_a_changed_python_default_makes_the_header_stale(tmp_path: Path) -> None:
    # The generator reads the Python of the checkout it runs in: a copy of firmware_py with one
    # default changed writes another header, so the freshness test above would fail.
    shutil.copytree(ROOT / "firmware_py", tmp_path / "firmware_py")
    cal = tmp_path / "firmware_py" / "calibration.py"
    cal.write_text(cal.read_text().replace("NOMINAL_MASS = 1296.0", "NOMINAL_MASS = 1400.0"))
    proc = subprocess.run([sys.executable, str(GENERATOR), str(tmp_path / "h.h")], capture_output=True, text=True,
                          env={"PYTHONPATH": str(tmp_path), "PATH": ""})
    assert proc.returncode == 0, proc.stderr
    changed = (tmp_path / "h.h").read_text()
    assert changed != HEADER.read_text()
    assert "#define MRS_CONTROLLER_DEFAULT_NOMINAL_MASS 1400.0" in changed
    assert "#define MRS_MONITOR_DEFAULT_NOMINAL_MASS 1400.0" in changed


def test_every_default_the_header_defines_is_used_by_the_port() -> None:
    defined = re.findall(r"^#define (MRS_\w+) ", HEADER.read_text(), flags=re.M)
    used = "".join(p.read_text() for p in [*PORT.glob("*.c"), *PORT.glob("*.h")] if p != HEADER)
    assert len(defined) > 70
    assert [name for name in defined if not re.search(rf"\b{name}\b", used)] == []


def test_the_generator_says_its_usage_on_bad_input() -> None:
    proc = subprocess.run([sys.executable, str(GENERATOR), "a", "b"], capture_output=True, text=True)
    assert proc.returncode == 2 and "unrecognized arguments: b" in proc.stderr


_PRINT_CONTROLLER = """
#include <stdio.h>
#include "mrs_controller.h"
int main(void)
{
    mrs_config_t c;
    int i;
    mrs_default_config(&c);
    printf("%d %d %d %d\\n", c.q_form == MRS_Q_LIMITED, c.method == MRS_TUSTIN, c.n_schedule, c.model_delay_steps);
    for (i = 0; i < c.n_schedule; ++i) {
        printf("%.17g %.17g %.17g %.17g\\n", c.schedule_speed[i], c.schedule_k[i], c.schedule_tau[i],
               c.schedule_tau_n[i]);
    }
    printf("%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\\n",
           c.model_actuator_tau, c.model_filter_hz, c.ts, c.aux_limit, c.rate_limit, c.fade_rate,
           c.speed_active_min, c.speed_max, c.driver_angle_max, c.yaw_rate_max, c.nominal_l_f, c.nominal_l_r,
           c.nominal_mass, c.nominal_c_f, c.nominal_c_r);
    return 0;
}
"""


@pytest.mark.skipif(CC is None, reason="gcc is not installed (.ci/run installs it)")
def test_the_c_controller_defaults_are_the_shipped_calibration(tmp_path: Path) -> None:
    (tmp_path / "p.c").write_text(_PRINT_CONTROLLER)
    exe = tmp_path / "p"
    subprocess.run([CC, "-std=c99", "-O2", "-ffp-contract=off", f"-I{PORT}", "-o", str(exe), str(tmp_path / "p.c"),
                    str(PORT / "mrs_controller.c"), "-lm"], check=True)
    lines = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.splitlines()
    c = calibration.ControllerConfig()
    assert c.q_form == calibration.Q_LIMITED and c.method == calibration.METHOD_TUSTIN
    assert lines[0].split() == ["1", "1", str(len(c.schedule_speed)), str(c.model_delay_steps)]
    table = [[float(x) for x in line.split()] for line in lines[1:-1]]
    assert table == [list(row) for row in zip(c.schedule_speed, c.schedule_k, c.schedule_tau, c.schedule_tau_n)]
    scalars = [f.name for f in dataclasses.fields(c)
               if isinstance(getattr(c, f.name), float) and f.name not in ("k", "tau", "tau_n")]
    assert [float(x) for x in lines[-1].split()] == [getattr(c, name) for name in scalars]
