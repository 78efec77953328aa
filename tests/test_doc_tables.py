"""The tables docs/controller.md generates from the code (tools/doc_tables.py) are current."""

from __future__ import annotations

import dataclasses

import pytest

import mrsteer_cli.doc_tables as dt
from firmware_py import plausibility as pl


def test_the_plausibility_table_in_the_doc_is_what_the_code_gives() -> None:
    assert dt.check(), f"docs/controller.md's table of PlausibilityConfig is stale: run `{dt.COMMAND}`"


def test_every_field_says_its_unit_and_meaning() -> None:
    comments = dt.field_comments(pl.PlausibilityConfig)
    assert [f.name for f in dataclasses.fields(pl.PlausibilityConfig)] == list(comments)
    assert all(unit and len(meaning) > 10 for unit, meaning in comments.values())


def test_a_hand_edited_value_is_found() -> None:
    text = dt.CONTROLLER_MD.read_text(encoding="utf-8")
    assert "| `yaw_bound` | 0.035 rad/s |" in text
    edited = text.replace("| `yaw_bound` | 0.035 rad/s |", "| `yaw_bound` | 0.04 rad/s |")
    assert dt.render(edited) == text


def test_bad_usage_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        dt.main([])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and "--write" in err, err
