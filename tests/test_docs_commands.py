"""Every command the README and ``docs/*.md`` show runs as written (tests/doc_commands.py).

The ``sh`` and ``python`` blocks run in a copy of the repository with the virtual environment
activated and ``MRSTEER_QUICK=1``; a block passes when every line exits 0 and nothing prints a
traceback.  Together they take minutes: ``make test-slow`` runs them (the offline blocks beside
its other tests, those that need the machine alone one at a time), ``make test`` the reader's own
tests below."""

from __future__ import annotations

from pathlib import Path

import pytest

import doc_commands as dc

_RUNNABLE = [b for b in dc.all_blocks() if b.tag != "skip"]
_QUIET = [pytest.param(b, id=b.name, marks=[pytest.mark.slow, pytest.mark.serial])
          for b in _RUNNABLE if dc.needs_quiet_machine(b)]
_OFFLINE = [pytest.param(b, id=b.name, marks=pytest.mark.slow) for b in _RUNNABLE if not dc.needs_quiet_machine(b)]


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One copy of the repository that the blocks needing the machine run in, in the docs' order."""
    return dc.repo_copy(tmp_path_factory.mktemp("docs") / "mrsteer")


@pytest.fixture(scope="module")
def offline_tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The offline blocks' copy of the repository."""
    return dc.repo_copy(tmp_path_factory.mktemp("docs-offline") / "mrsteer")


@pytest.mark.parametrize("block", _QUIET)
def test_doc_block_runs_as_written(block: dc.Block, tree: Path) -> None:
    _runs_clean(block, tree)


@pytest.mark.parametrize("block", _OFFLINE)
def test_offline_doc_block_runs_as_written(block: dc.Block, offline_tree: Path) -> None:
    _runs_clean(block, offline_tree)


def _runs_clean(block: dc.Block, tree: Path) -> None:
    proc = dc.run(block, tree)
    shown = f"{block.name}:\n{block.script}--- stdout\n{proc.stdout[-3000:]}--- stderr\n{proc.stderr[-3000:]}"
    assert proc.returncode == 0, shown
    assert "Traceback (most recent call last)" not in proc.stdout + proc.stderr, shown


def test_realtime_runs_and_benchmarks_need_the_machine_and_computation_does_not(tmp_path: Path) -> None:
    def block(*commands: str) -> dc.Block:
        return dc.Block(tmp_path / "x.md", 1, commands)

    for quiet in ("mrsteer hil run --scenario handover --mode realtime", "mrsteer bench --quick", "make demo",
                  "mrsteer faults run --secoc", "mrsteer controller &", "mrsteer hil run --controller-cmd x",
                  "mrsteer hil demo", "sudo tools/vcan.sh up 2"):
        assert dc.needs_quiet_machine(block("mrsteer design busload", quiet)), quiet
    for offline in ("mrsteer design margins --reference   # about 10 min", "mrsteer hil run --scenario s.toml",
                    "mrsteer campaign run campaigns/example.toml --out out/camp", "make -C ports/c check",
                    "cantools decode dbc/mrsteer.dbc < out/run1/traffic.log", "mrsteer hil evidence"):
        assert not dc.needs_quiet_machine(block(offline)), offline


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
