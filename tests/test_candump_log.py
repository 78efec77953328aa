"""The candump -L log codec: the lines the bus logger writes (as the real ``candump -L`` does),
read back exactly, and readable by ``cantools``."""

from __future__ import annotations

import io
from pathlib import Path

import can
import cantools.logreader
import pytest

from sim_plant.nodes.candump_log import Frame, LogError, format_line, read_candump, read_candump_messages

CASES = [
    (can.Message(timestamp=1700000000.123456, arbitration_id=0x101, data=bytes([0x00, 0x11, 0xAA]),
                 is_extended_id=False), "(1700000000.123456) vcan0 101#0011AA\n"),
    (can.Message(timestamp=1700000000.5, arbitration_id=0x1ABCDEF, data=b"", is_extended_id=True),
     "(1700000000.500000) vcan0 01ABCDEF#\n"),
    (can.Message(timestamp=1700000001.000001, arbitration_id=0x0A0, is_remote_frame=True, dlc=2,
                 is_extended_id=False), "(1700000001.000001) vcan0 0A0#R\n"),
    (can.Message(timestamp=1700000002.25, arbitration_id=0x7F0, data=bytes(range(12)), is_fd=True,
                 bitrate_switch=True, is_extended_id=False), "(1700000002.250000) vcan0 7F0##1000102030405060708090A0B\n"),
]


@pytest.mark.parametrize("msg,line", CASES)
def test_a_frame_is_written_as_candump_L_writes_it(msg: can.Message, line: str) -> None:
    assert format_line(msg, "vcan0") == line


def test_the_log_reads_back_to_the_microsecond_in_order(tmp_path: Path) -> None:
    # Not sorted, not clamped: a frame logged with an older stamp keeps it.
    log = tmp_path / "traffic.log"
    log.write_text("".join(line for _, line in CASES) + "(1700000000.000007) other 102#FF\n")
    assert read_candump(log) == [
        Frame(1700000000.123456, 0x101, bytes([0x00, 0x11, 0xAA])), Frame(1700000000.5, 0x1ABCDEF, b""),
        Frame(1700000001.000001, 0x0A0, b""), Frame(1700000002.25, 0x7F0, bytes(range(12))),
        Frame(1700000000.000007, 0x102, b"\xff")]


def test_what_the_logger_writes_is_what_cantools_reads() -> None:
    text = "".join(format_line(msg, "vehicle") for msg, _ in CASES)
    parsed = list(cantools.logreader.Parser(io.StringIO(text)))
    assert [(f.channel, f.frame_id, f.is_extended_frame, f.is_remote_frame, f.data) for f in parsed] == [
        ("vehicle", 0x101, False, False, bytes([0x00, 0x11, 0xAA])), ("vehicle", 0x1ABCDEF, True, False, b""),
        ("vehicle", 0x0A0, False, True, b""), ("vehicle", 0x7F0, False, False, bytes(range(12)))]
    assert [f.timestamp.timestamp() for f in parsed][0] == pytest.approx(1700000000.123456, abs=1e-7)


@pytest.mark.parametrize("cut", ["(1700000000.600000) vcan0 101#0011A", "(1700000000.600000) vca", "(17"])
def test_a_cut_off_last_line_is_left_out_with_one_warning_naming_it(tmp_path: Path, cut: str) -> None:
    log = tmp_path / "traffic.log"
    whole = [line for _, line in CASES[:2]]
    log.write_text("".join(whole) + "\n" + cut)  # a blank line, then a logger killed mid-write
    warnings: list[str] = []
    assert read_candump(log, warnings.append) == [
        Frame(1700000000.123456, 0x101, bytes([0x00, 0x11, 0xAA])), Frame(1700000000.5, 0x1ABCDEF, b"")]
    assert warnings == [f"{log}: line 4 is cut off (no end of line) and left out; the 2 frames before it are read"]


def test_a_bad_line_before_the_last_is_still_refused_by_its_number(tmp_path: Path) -> None:
    log = tmp_path / "traffic.log"
    log.write_text(CASES[0][1] + "(1700000000.6) vca\n" + CASES[1][1])
    with pytest.raises(LogError, match=r"traffic.log: line 2: not a candump -L frame"):
        read_candump_messages(log, lambda m: pytest.fail(m))
