"""The tables the docs generate from the code and from committed run outputs (tools/doc_tables.py)
are current."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

import mrsteer_cli.doc_tables as dt
from firmware_py import plausibility as pl


def test_the_plausibility_table_in_the_doc_is_what_the_code_gives() -> None:
    assert dt.check(dt.CONTROLLER_MD), f"docs/controller.md's table of PlausibilityConfig is stale: run `{dt.COMMAND}`"


def test_every_field_says_its_unit_and_meaning() -> None:
    comments = dt.field_comments(pl.PlausibilityConfig)
    assert [f.name for f in dataclasses.fields(pl.PlausibilityConfig)] == list(comments)
    assert all(unit and len(meaning) > 10 for unit, meaning in comments.values())


def test_a_hand_edited_value_is_found() -> None:
    text = dt.CONTROLLER_MD.read_text(encoding="utf-8")
    assert "| `yaw_bound` | 0.035 rad/s |" in text
    edited = text.replace("| `yaw_bound` | 0.035 rad/s |", "| `yaw_bound` | 0.04 rad/s |")
    assert dt.render(edited) == text


def test_every_generated_table_is_current() -> None:
    assert dt.stale() == [], f"run `{dt.COMMAND}`"


def test_every_table_has_its_markers_once() -> None:
    for name, (path, _) in dt.TABLES.items():
        assert path.read_text(encoding="utf-8").count(dt.begin(name)) == 1, (name, path)


def test_a_hand_edited_bus_load_is_found() -> None:
    text = dt.DESIGN_MD.read_text(encoding="utf-8")
    row = "| 500 Hz | 32.8 % | 39.8 % |"
    assert row in text
    assert dt.render(text.replace(row, "| 500 Hz | 30.0 % | 39.8 % |"), dt.DESIGN_MD) == text


def test_the_campaign_table_follows_its_summaries(tmp_path: Path) -> None:
    """A summary's figures, not typed ones, make the row: change the summary and the row changes."""
    src = sorted(dt.CAMPAIGN_RESULTS.glob("*.json"))[0]
    summary = json.loads(src.read_text(encoding="utf-8"))
    name, cal = next(iter(summary["calibrations"].items()))
    cal["runs"], cal["passed"], cal["pass_rate"] = 10, 7, 0.7
    (tmp_path / src.name).write_text(json.dumps(summary), encoding="utf-8")
    table = dt.campaign_results_table(tmp_path)
    assert f"| `{src.stem}` | {name} | 10 | 7 (70.0 %) |" in table
    assert f"| `{src.stem}` | {name} | 10 | 7 (70.0 %) |" not in dt.campaign_results_table()


def test_the_tradeoff_table_follows_its_json(tmp_path: Path) -> None:
    data = json.loads(dt.TRADEOFF_JSON.read_text(encoding="utf-8"))
    data["rows"]["shipped schedule"]["reference"]["gain_margin_db"] = 1.5
    edited = tmp_path / "tradeoff.json"
    edited.write_text(json.dumps(data), encoding="utf-8")
    row = next(r for r in dt.tradeoff_table(edited).splitlines() if r.startswith("| shipped schedule | reference |"))
    assert row.split(" | ")[3] == "1.50"
    assert "| shipped schedule | reference | yes (0.9990) | 8.24 |" in dt.tradeoff_table()


def test_bad_usage_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        dt.main([])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and "--write" in err, err


def test_a_broken_summary_is_one_line_and_exit_2(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "cut-short.json").write_text('{"campaign": ', encoding="utf-8")
    monkeypatch.setattr(dt, "CAMPAIGN_RESULTS", tmp_path)
    assert dt.main(["--check"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cut-short.json" in err, err
