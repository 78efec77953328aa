"""``mrsteer hil evidence``: the realistic scenarios on the bus with and without the controller, one
table, and its outputs written whole or not at all."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from mrsteer_cli.cli import main
from sim_plant.harness import hil, hil_evidence


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.slow
def test_hil_evidence_as_the_readme_writes_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """README: ``mrsteer hil evidence``, shortened to one scenario of 1.5 s (--quick) so that it
    takes seconds: real processes on the fallback bus, with the shipped (scheduled) gains."""
    out = tmp_path / "evidence"
    assert main(["hil", "evidence", "--quick", "--scenario", "side-wind", "--out", str(out)]) == 0
    printed = capsys.readouterr()
    table = printed.out.splitlines()
    assert table[3].split()[0] == "side-wind"
    assert "controller limited, gains scheduled over v 5/10/20/30/40/50 m/s: K 10.4/27/10/10/6.3/4.5" in printed.out
    assert table[-1] == "runs of side-wind 1.5 s"
    assert (out / "evidence.txt").read_text() == printed.out
    rows = json.loads((out / "evidence.json").read_text())
    summaries = {sub: json.loads((out / "side-wind" / sub / "summary.json").read_text())
                 for sub in ("with-controller", "without-controller")}
    assert rows[0]["peak_yaw_rate_on_rad_s"] == summaries["with-controller"]["peak_yaw_rate_rad_s"]
    assert rows[0]["peak_yaw_rate_off_rad_s"] == summaries["without-controller"]["peak_yaw_rate_rad_s"]
    assert rows[0]["reduction"] > 0.5  # the controller rejects the gust
    # progress names where the runs end up, and the scratch directory is gone
    assert ".tmp" not in printed.err and f"to {out}/" in printed.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["evidence"]


def test_a_failed_evidence_leaves_its_out_as_it_was(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A run that fails after others have written theirs: nothing of this evidence is left, and
    what ``--out`` held before is untouched."""
    out = tmp_path / "evidence"
    (out / "split-mu" / "with-controller").mkdir(parents=True)
    (out / "split-mu" / "with-controller" / "summary.json").write_text("{}\n")
    (out / "mine.txt").write_text("kept\n")
    before = _tree(out)
    calls: list[str] = []

    def fake_run(cfg: hil.HilConfig, progress: Any = None) -> Any:
        """split-mu's two runs write their outputs; side-wind's first fails half-way."""
        calls.append(cfg.scenario)
        cfg.out.mkdir(parents=True, exist_ok=True)  # as hil.run does
        (cfg.out / "traffic.log").write_text("a run's log\n")
        if len(calls) == 3:
            raise hil.HilError("plant exited with status 1")
        return SimpleNamespace(summary={})

    monkeypatch.setattr(hil, "run", fake_run)
    assert main(["hil", "evidence", "--out", str(out)]) == 2  # a run that failed: an error, not a verdict
    assert calls == ["split-mu", "split-mu", "side-wind"]
    assert "plant exited with status 1" in capsys.readouterr().err
    assert _tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["evidence"]  # no scratch directory left


def test_evidence_output_that_is_a_file_is_one_line_and_exit_2(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "taken"
    out.write_text("a file\n")
    assert main(["hil", "evidence", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a directory" in err
    assert out.read_text() == "a file\n" and sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def test_quick_ends_each_scenario_a_second_after_its_last_event() -> None:
    assert [hil_evidence.quick_duration(n) for n in hil_evidence.SCENARIOS] == [1.5, 1.5, 1.5]
    assert hil_evidence.quick_duration("paper-fig9") == 1.5
