"""The layering the project promises (docs/architecture.md), checked on the code itself."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_import_contracts_are_kept() -> None:
    lint = Path(sys.executable).with_name("lint-imports")
    proc = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    contracts = PYPROJECT["tool"]["importlinter"]["contracts"]
    assert f"Contracts: {len(contracts)} kept, 0 broken." in proc.stdout


def test_every_package_is_placed_in_a_layer() -> None:
    """A new subpackage that no contract names would escape the layering unnoticed."""
    named = set()
    for c in PYPROJECT["tool"]["importlinter"]["contracts"]:
        for entry in c.get("layers", []) + c.get("source_modules", []):
            named.update(part.strip() for part in entry.replace(":", "|").split("|"))
    packages = PYPROJECT["tool"]["setuptools"]["packages"]
    for pkg in packages:
        top = pkg.split(".")[0]
        assert top in named, f"{top} is in no layers contract"
        if pkg.count(".") == 1 and pkg.split(".")[0] in ("firmware_py", "sim_plant", "mrsteer_dbc"):
            assert pkg in named, f"{pkg} is in no layers contract"


def test_the_car_may_take_nothing_of_the_firmware_but_its_calibration() -> None:
    """The car's contract forbids every firmware module but the calibration (decision 0010), so a
    new firmware module is forbidden to the car until someone decides otherwise."""
    (car,) = [c for c in PYPROJECT["tool"]["importlinter"]["contracts"] if c.get("source_modules") == ["sim_plant.car"]]
    firmware = ROOT / "firmware_py"
    modules = {f"firmware_py.{p.stem}" for p in firmware.glob("*.py") if p.stem != "__init__"}
    modules |= {f"firmware_py.{p.parent.name}" for p in firmware.glob("*/__init__.py")}
    assert modules - set(car["forbidden_modules"]) == {"firmware_py.calibration"}


PORTING_REFERENCE = ("model_regulator", "calibration", "calibration_file", "plausibility", "authority", "cycle")


@pytest.mark.parametrize("module", PORTING_REFERENCE)
def test_the_porting_reference_imports_the_standard_library_only(module: str) -> None:
    tree = ast.parse((ROOT / "firmware_py" / f"{module}.py").read_text())
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            imported.add(node.module or "")
    assert imported, "no imports found: the check is looking at the wrong file"
    ours = {f"firmware_py.{m}" for m in PORTING_REFERENCE}
    outside = {m for m in imported - ours if m.split(".")[0] not in set(sys.stdlib_module_names) | {"__future__"}}
    assert not outside, outside


def test_the_mrsteer_can_interface_is_registered_for_python_can() -> None:
    """`python -m can.logger -i mrsteer` and `can.Bus(interface="mrsteer")` find the fallback bus."""
    from importlib.metadata import entry_points

    import can

    from firmware_py.platform.fallback_bus import FallbackBus

    (ep,) = [e for e in entry_points(group="can.interface") if e.name == "mrsteer"]
    assert ep.load() is FallbackBus
    assert can.util.load_config(config={"interface": "mrsteer", "channel": "x"})["interface"] == "mrsteer"


def test_the_process_entry_points_keep_their_names() -> None:
    for module, words in (("firmware_py", "controller"), ("sim_plant", "car")):
        proc = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0, proc.stderr
        assert f"python -m {module}" in proc.stdout and words in proc.stdout
