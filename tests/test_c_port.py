"""The C99 reference port (ports/c) against the golden vectors, and the cantools-generated C
codec and the C E2E functions against the Python ones."""

from __future__ import annotations

import random
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import mrsteer_dbc
from mrsteer_dbc import E2EReceiver

ROOT = Path(__file__).resolve().parents[1]
PORT = ROOT / "ports" / "c"
VECTOR_DIR = Path(__file__).parent / "vectors"
FILES = sorted(VECTOR_DIR.glob("*__*.csv"))
CC = shutil.which("gcc")
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-ffp-contract=off"]

pytestmark = pytest.mark.skipif(CC is None, reason="gcc is not installed (.ci/run installs it)")

# float32: state bound on |u_C - u_Python| in rad over the vectors (see docs/porting.md).
F32_BOUND_LIMITED = 1e-5
F32_BOUND_STANDARD = 1e-4


def _cc(out: Path, *sources: str, defines: tuple[str, ...] = (), include: Path = PORT) -> Path:
    cmd = [CC, *CFLAGS, *defines, f"-I{include}", "-I" + str(PORT), "-o", str(out), *sources, "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="module")
def runners(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cport")
    src = [str(PORT / f) for f in ("mrs_controller.c", "mrs_config.c", "mrs_vectors.c", "run_vectors.c")]
    return {"f64": _cc(d / "rv64", *src), "f32": _cc(d / "rv32", *src, defines=("-DMRS_FLOAT32",))}


def _run(runner: Path, path: Path) -> dict[str, float]:
    cfg = VECTOR_DIR / f"{path.stem.split('__')[0]}.cfg"
    proc = subprocess.run([str(runner), str(cfg), str(path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return {k: float(v) for k, v in re.findall(r"(\w+)=(\S+)", proc.stdout)}


MISMATCHES = ("status_mismatch", "flags_mismatch", "idx_mismatch", "init_mismatch")


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_float64_build_reproduces_every_vector_bit_for_bit(runners: dict[str, Path], path: Path) -> None:
    r = _run(runners["f64"], path)
    assert r["real_bytes"] == 8 and r["steps"] > 100
    assert r["coeff_rel_err"] == 0.0
    for q in ("u", "z", "hist", "model"):
        assert r[f"{q}_err"] == 0.0, q  # same operations in the same order: the same doubles
    assert all(r[m] == 0 for m in MISMATCHES)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_float32_build_stays_within_its_stated_bound(runners: dict[str, Path], path: Path) -> None:
    r = _run(runners["f32"], path)
    assert r["real_bytes"] == 4
    bound = F32_BOUND_STANDARD if "standard" in path.stem else F32_BOUND_LIMITED
    assert r["u_err"] <= bound and r["hist_err"] <= bound and r["model_err"] <= bound
    assert r["z_err"] <= 10 * bound
    assert all(r[m] == 0 for m in MISMATCHES)


def test_step_calls_nothing_and_the_port_needs_only_exp(tmp_path: Path) -> None:
    obj = tmp_path / "mrs_controller.o"
    proc = subprocess.run([CC, *CFLAGS, "-c", "-o", str(obj), str(PORT / "mrs_controller.c")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    undefined = subprocess.run(["nm", "-u", str(obj)], capture_output=True, text=True, check=True).stdout.split()
    # no heap, no I/O; exp(), tan() and sqrt() only in mrs_configure (ZOH, nominal actuator and filter)
    assert set(undefined) - {"U"} <= {"exp", "tan", "sqrt"}
    dis = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(obj)], capture_output=True, text=True,
                         check=True).stdout
    step = dis.split("<mrs_step>:")[1].split("\n\n")[0]
    assert "call" not in step  # no function call, hence no recursion


@pytest.fixture(scope="module")
def codec(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("codec")
    gen = subprocess.run([sys.executable, "-m", "cantools", "generate_c_source", str(mrsteer_dbc.DBC_PATH),
                          "-o", str(d)], capture_output=True, text=True)
    assert gen.returncode == 0, gen.stderr
    subprocess.run([sys.executable, str(PORT / "gen_codec_check.py"), str(mrsteer_dbc.DBC_PATH), "mrsteer",
                    str(d / "codec_check.c")], check=True)
    return _cc(d / "codec_check", str(d / "mrsteer.c"), str(d / "codec_check.c"), str(PORT / "mrs_e2e.c"), include=d)


def _random_values(msg, rng: random.Random) -> dict[str, float]:
    values = {}
    for s in msg.signals:
        lo, hi = s.minimum, s.maximum
        raw_lo, raw_hi = round((lo - s.offset) / s.scale), round((hi - s.offset) / s.scale)
        values[s.name] = rng.randint(raw_lo, raw_hi) * s.scale + s.offset
    return values


def test_generated_codec_packs_and_unpacks_every_message_like_python(codec: Path) -> None:
    c = mrsteer_dbc.load()
    rng = random.Random(20261122)
    lines, expected = [], []
    for msg in c.db.messages:
        e2e = c.e2e(msg.name)
        for _ in range(200):
            values = _random_values(msg, rng)
            if e2e is not None:
                data = c.encode(msg.name, {k: v for k, v in values.items()
                                           if k not in (e2e.crc_signal, e2e.counter_signal)},
                                int(values[e2e.counter_signal]))
                lines.append(f"{msg.frame_id:X} {e2e.data_id} {e2e.crc_byte} {data.hex().upper()}")
            else:
                data = msg.encode(values, strict=True)
                lines.append(f"{msg.frame_id:X} -1 0 {data.hex().upper()}")
            expected.append((msg, data, e2e))
    proc = subprocess.run([str(codec)], input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout.splitlines()
    assert len(out) == len(expected)
    for line, (msg, data, e2e) in zip(out, expected):
        fid, repacked, crc, *sigs = line.split()
        assert int(fid, 16) == msg.frame_id
        assert repacked == data.hex().upper()  # C pack(unpack(x)) == the Python encoding
        if e2e is not None:
            assert int(crc) == data[e2e.crc_byte]  # the C E2E CRC is the one Python put there
        py = msg.decode(data, decode_choices=False)
        for item in sigs:
            name, value = item.split("=")
            assert float(value) == pytest.approx(py[name], rel=1e-12, abs=1e-12), (msg.name, name)


def test_c_alive_counter_and_receiver_match_python(tmp_path: Path) -> None:
    exe = _cc(tmp_path / "e2e_check", str(PORT / "e2e_check.c"), str(PORT / "mrs_e2e.c"))
    rng = random.Random(7)
    counters = [rng.choice([0, 1, 1, 1, 2, 4, 7]) for _ in range(500)]
    seq, x = [], 3
    for step in counters:
        x = (x + step) % mrsteer_dbc.COUNTER_MODULO
        seq.append(x)
    proc = subprocess.run([str(exe)], input="3\n" + "\n".join(map(str, seq)) + "\n", capture_output=True,
                          text=True, timeout=60, check=True)
    codes = {0: "OK", 1: "OK_SOME_LOST", 2: "INITIAL", 3: "REPEATED", 4: "WRONG_SEQUENCE"}
    rx, alive = E2EReceiver(3), mrsteer_dbc.AliveCounter()
    seen = set()
    for value, line in zip(seq, proc.stdout.splitlines()):
        status, nxt = map(int, line.split())
        expected = rx.check(value)
        assert codes[status] == expected.name
        alive.value = value
        assert nxt == alive.next()
        seen.add(expected.name)
    assert seen == set(codes.values())


def test_c_e2e_crc_equals_the_autosar_e2e_library(tmp_path: Path) -> None:
    """mrs_e2e_crc against the independent `autosar-e2e` package (e2e_p01_protect, data ID mode
    BOTH) on random bytes of every E2E message, with the CRC byte's old content random too."""
    import e2e.p01 as e2e_p01  # autosar-e2e, in the test extra
    exe = _cc(tmp_path / "e2e_check", str(PORT / "e2e_check.c"), str(PORT / "mrs_e2e.c"))
    c = mrsteer_dbc.load()
    rng = random.Random(17)
    lines, expected = [], []
    for msg in c.db.messages:
        e2e = c.e2e(msg.name)
        if e2e is None:
            continue
        for _ in range(300):
            data = bytearray(rng.randbytes(msg.length))
            data[1] = (data[1] & 0xF0) | rng.randrange(15)
            lines.append(f"{e2e.data_id} {e2e.crc_byte} {data.hex()}")
            e2e_p01.e2e_p01_protect(data, e2e.data_id, increment_counter=False)
            expected.append(data[e2e.crc_byte])
    proc = subprocess.run([str(exe)], input="crc\n" + "\n".join(lines) + "\n", capture_output=True, text=True,
                          timeout=60, check=True)
    got = [int(x) for x in proc.stdout.split()]
    assert len(got) == len(expected) == 6 * 300  # six E2E messages
    assert got == expected
    assert int(subprocess.run([str(exe)], input="crc\n4353 0 DF00000000000000\n", capture_output=True, text=True,
                              check=True).stdout) == 0xA3  # issue 17's demo frame
