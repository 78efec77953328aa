"""Every command the README and ``docs/*.md`` show runs as written (tests/doc_commands.py).

The ``sh`` and ``python`` blocks run in a copy of the repository with the virtual environment
activated and ``MRSTEER_QUICK=1``; a block passes when every line exits 0 and nothing prints a
traceback.  Together they take minutes: ``make test-slow`` runs them, ``make test`` the reader's
own tests below."""

from __future__ import annotations

from pathlib import Path

import pytest

import doc_commands as dc

_RUNNABLE = [b for b in dc.all_blocks() if b.tag != "skip"]


def _param(block: dc.Block) -> object:
    return pytest.param(block, id=block.name, marks=[pytest.mark.slow, pytest.mark.serial])


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One copy of the repository that every block runs in, in the docs' order."""
    return dc.repo_copy(tmp_path_factory.mktemp("docs") / "mrsteer")


@pytest.mark.parametrize("block", [_param(b) for b in _RUNNABLE])
def test_doc_block_runs_as_written(block: dc.Block, tree: Path) -> None:
    proc = dc.run(block, tree)
    shown = f"{block.name}:\n{block.script}--- stdout\n{proc.stdout[-3000:]}--- stderr\n{proc.stderr[-3000:]}"
    assert proc.returncode == 0, shown
    assert "Traceback (most recent call last)" not in proc.stdout + proc.stderr, shown


def test_every_skipped_block_says_why() -> None:
    unexplained = [b.name for b in dc.all_blocks() if b.tag == "skip" and not b.reason]
    assert not unexplained


def test_inline_commands_are_also_in_a_block() -> None:
    """A whole command line shown inline in prose is one a reader would type: it must be in a
    block too, where it runs."""
    assert dc.inline_commands_outside_blocks() == []


def test_the_reader_parses_tags_and_commands(tmp_path: Path) -> None:
    doc = tmp_path / "x.md"
    doc.write_text("text\n<!-- doc-test: skip: CI runs it -->\n```sh\nmake test   # all\n\n# note\n```\n"
                   "```toml\nkey = 1\n```\n```sh\nmrsteer sim paper\n```\n")
    got = dc.blocks(doc)
    assert [(b.line, b.commands, b.tag, b.reason) for b in got] == [
        (3, ("make test   # all",), "skip", "CI runs it"), (11, ("mrsteer sim paper",), None, "")]
