"""Behaviour identity of the plausibility monitor: digests of everything it does over a large,
varied input set, in Python and in C, to compare before and after a change that must not alter
behaviour (issue 52: the monitor split into its checks).

    python tools/monitor_identity.py            # print the digests
    python tools/monitor_identity.py --quick    # a tenth of the input set

Inputs: the golden vectors' inputs (tests/vectors, as a car with exact redundant sensors) and
seeded sequences of randomized and scenario-like rows (steady turns with a wrong speed, braking
with wheel slip, speed steps, frozen, offset and jumping sensors, low speed, missing frames, NaN
and inf), each sequence from a reset monitor.  Recorded per row:

- ``python-state``: the bits, the flags and every slot of ``MonitorState`` (repr), and the
  authority limiter's command and flags on the monitor's cut and fade;
- ``python-rows`` / ``c-rows``: the row the C monitor runner (ports/c/monitor_vectors.c) prints,
  formatted as it does (``%.17g``), from Python and from the C port;
- ``python-cycle`` / ``c-cycle``: the command, plausibility bits and monitor flags of one control
  cycle per row (``firmware_py.cycle.step``; the C cycle through the campaign's cffi batch).

Python and C digests of the same name must be equal to each other, and every digest equal before
and after a refactor.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from firmware_py import authority as au
from firmware_py import cycle
from firmware_py import model_regulator as mr
from firmware_py import plausibility as pl

ROOT = Path(__file__).resolve().parents[1]
PORT = ROOT / "ports" / "c"
VECTORS = ROOT / "tests" / "vectors"
NAN, INF = math.nan, math.inf
Row = tuple[float, float, float, float, float, float, float, float, float]
# dd, dd2, r, ay, v, aux, u_request, r2, v2 (the C runner's row)


def _vector_sequences() -> list[list[Row]]:
    out = []
    for path in sorted(VECTORS.glob("*__*.csv")):
        with path.open() as f:
            rows = list(csv.reader(f))[1:]
        seq = []
        for row in rows:
            d, r, v = float(row[1]), float(row[2]), float(row[3])
            seq.append((d, d, r, r * v, v, 0.0, 0.5 * d, r, v))
        out.append(seq)
    return out


def _random_sequence(rng: np.random.Generator, n: int) -> list[Row]:
    """One sequence of a randomly chosen scenario family."""
    kind = int(rng.integers(0, 8))
    c = pl.configure(pl.PlausibilityConfig())
    k = np.arange(n)
    v0 = float(rng.choice([3.0, 6.0, 12.0, 25.0, 40.0]))
    v = np.full(n, v0)
    if kind == 1:  # braking: the speed falls, the second speed slips below it
        v = np.maximum(v0 + 10.0 - float(rng.uniform(0.5, 9.0)) * k * 0.002, 0.0)
    if kind == 2:  # speed steps and drifts
        v = v + np.where(k > n // 3, float(rng.uniform(-3, 3)), 0.0) + k * float(rng.uniform(-2e-3, 2e-3))
    r_amp = float(rng.choice([0.0, 0.05, 0.2, 0.4]))
    r = r_amp * np.sin(k * float(rng.uniform(1e-3, 2e-2))) + rng.normal(0, 0.003, n)
    if kind == 3:  # steady turn
        r = np.full(n, float(rng.choice([-1, 1])) * float(rng.uniform(0.1, 0.5))) + rng.normal(0, 1e-3, n)
    vs = np.maximum(v, 1.0)
    d = r * (c.wheelbase + c.k_us * vs * vs) / vs * float(rng.uniform(0.7, 1.3)) + rng.normal(0, 1e-3, n)
    ay = r * v * float(rng.uniform(0.9, 1.1)) + rng.normal(0, 0.05, n)
    held = 25  # the redundant frame: 50 ms of 2 ms periods
    ay = np.repeat(ay[::held], held)[:n]
    dd2 = np.repeat((d + rng.normal(0, 5e-4, n))[::held], held)[:n]
    r2 = r + rng.normal(0, 0.003, n)
    v2 = np.repeat((v + rng.normal(0, 0.05, n))[::held], held)[:n]
    if kind == 1:
        v2 = v2 * float(rng.uniform(0.7, 1.0))
    aux = rng.normal(0, 0.01, n) * float(rng.choice([0.0, 1.0]))
    u = rng.normal(0, 0.05, n)
    onset = int(rng.integers(0, n))
    if kind == 4:  # a sensor fault from onset: offset, scale, stuck or jump
        which = int(rng.integers(0, 6))
        col = [r, ay, d, dd2, v, r2][which]
        how = int(rng.integers(0, 3))
        if how == 0:
            col[onset:] += float(rng.normal(0, 0.1)) * (10.0 if which in (1, 4) else 1.0)
        elif how == 1:
            col[onset:] *= float(rng.uniform(0.5, 1.5))
        else:
            col[onset:] = col[onset]
    if kind == 5:  # frozen values against moving partners
        frozen = [r, ay, d, dd2][int(rng.integers(0, 4))]
        frozen[onset:onset + 400] = frozen[onset]
    if kind == 6:  # steering jumps
        for j in rng.integers(0, n, 5):
            d[j:] += float(rng.choice([-1, 1])) * 0.02
    seq = [tuple(float(x) for x in row) for row in zip(d, dd2, r, ay, v, aux, u, r2, v2)]
    # missing inputs and non-finite values
    p_nan = float(rng.choice([0.0, 0.002, 0.02]))
    no_r2 = bool(rng.integers(0, 2))
    no_v2 = bool(rng.integers(0, 2))
    out = []
    for j, row in enumerate(seq):
        x = list(row)
        if no_r2:
            x[7] = NAN
        if no_v2:
            x[8] = NAN
        if kind == 7 and n // 3 <= j < n // 2:
            x[3] = x[1] = NAN  # the redundant frame lost for a while
        if p_nan and rng.random() < p_nan:
            x[int(rng.integers(0, 9))] = float(rng.choice([NAN, INF, -INF, 1e4]))
        out.append(tuple(x))
    return out


def sequences(quick: bool) -> list[list[Row]]:
    rng = np.random.default_rng(52)
    count = 30 if quick else 300
    return _vector_sequences() + [_random_sequence(rng, int(rng.integers(200, 2500))) for _ in range(count)]


def _g(x: float) -> str:
    return "%.17g" % x


def python_rows(seqs: list[list[Row]]) -> tuple[str, str, list[str]]:
    """Digests of the monitor's full state and of the runner's rows; the rows themselves."""
    m, a = pl.PlausibilityConfig(), au.AuthorityConfig()
    mc, ac = pl.configure(m), au.configure_authority(a)
    h_state, h_rows, lines = hashlib.sha256(), hashlib.sha256(), []
    seen = [0] * 16  # sequences in which each flag was set
    slots = pl.MonitorState.__slots__
    for seq in seqs:
        ms, ast = pl.MonitorState(), au.AuthorityState()
        text, ored = [], 0
        for dd, dd2, r, ay, v, aux, u, r2, v2 in seq:
            bits = pl.monitor_step(mc, ms, dd, dd2, r, ay, v, aux, r2, v2)
            u_out = au.authority_step(ac, ast, u, bits, ms.flags & pl.CUT_CHECKS, ms.flags & pl.FADE_CHECKS)
            ored |= ms.flags
            h_state.update(repr((bits, u_out, ast.flags, [getattr(ms, n) for n in slots])).encode())
            text.append(" ".join((str(bits), str(ms.flags), _g(ms.kin_err), _g(ms.pair_err), _g(ms.model_err),
                                  _g(u_out), str(ast.flags), _g(ms.yaw_pair_err), _g(ms.turn_err), str(ms.turn_n),
                                  str(int(ms.turn_settled)), str(ms.yaw_hold_n), str(ms.yaw_clear_n),
                                  _g(ms.speed_pair_err), str(ms.speed_pair_count), str(int(ms.speed2_seen)),
                                  str(ms.steer_hold_n), _g(ms.speed_lag))))
        for b in range(16):
            seen[b] += (ored >> b) & 1
        block = "\n".join(text) + "\n"
        h_rows.update(block.encode())
        lines.append(block)
    print("flags set in sequences: " + " ".join(f"{1 << b:#x}:{n}" for b, n in enumerate(seen) if n or b < 15))
    return h_state.hexdigest(), h_rows.hexdigest(), lines


def c_rows(seqs: list[list[Row]]) -> tuple[str, list[str]] | None:
    cc = shutil.which("gcc")
    if cc is None:
        return None
    m, a = pl.PlausibilityConfig(), au.AuthorityConfig()
    head = ("monitor " + " ".join(repr(float(getattr(m, f.name))) for f in dataclasses.fields(m)) + "\n"
            + "authority " + " ".join(repr(float(getattr(a, f.name))) for f in dataclasses.fields(a)) + "\n")
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(tmp) / "monitor_vectors"
        subprocess.run([cc, "-std=c99", "-O2", "-ffp-contract=off", f"-I{PORT}", "-o", str(exe),
                        str(PORT / "mrs_monitor.c"), str(PORT / "monitor_vectors.c"), "-lm"], check=True)
        h, lines = hashlib.sha256(), []
        for seq in seqs:
            text = head + "".join(" ".join(repr(x) for x in row) + "\n" for row in seq)
            out = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True).stdout
            block = out.split("\n", 1)[1]  # past the coeffs line
            h.update(block.encode())
            lines.append(block)
    return h.hexdigest(), lines


def _cycle_record(h: hashlib._Hash, u: float, plaus: int, flags: int) -> None:
    h.update(f"{u!r} {plaus} {flags}\n".encode())


def python_cycle(seqs: list[list[Row]]) -> str:
    law = mr.ControllerConfig()
    h = hashlib.sha256()
    for seq in seqs:
        cyc = cycle.Cycle(law)
        i = cycle.CycleInputs()
        for dd, dd2, r, ay, v, _aux, _u, r2, v2 in seq:
            i.delta_driver, i.delta_driver_redundant, i.yaw_rate, i.lat_accel = dd, dd2, r, ay
            i.speed, i.yaw_rate_redundant, i.speed_redundant, i.monitor_driver = v, r2, v2, dd
            u = cyc.step(i)
            _cycle_record(h, u, cyc.state.plausibility, cyc.state.monitor.flags)
    return h.hexdigest()


def c_cycle(seqs: list[list[Row]]) -> str | None:
    from sim_plant.campaign import c_cycle as cc
    try:
        cc.require()
    except Exception:  # noqa: BLE001 - no build: no C digest
        return None
    law = mr.ControllerConfig()
    n = len(seqs)
    batch = cc.CycleBatch(law, law.aux_limit, n)
    length = max(len(s) for s in seqs)
    cols = np.full((length, n, 9), NAN)
    for j, seq in enumerate(seqs):
        cols[:len(seq), j, :] = np.array(seq)
    records: list[list[str]] = [[] for _ in range(n)]
    for k in range(length):
        x = cols[k]
        u = batch.step(x[:, 0], x[:, 1], x[:, 2], x[:, 3], x[:, 4], x[:, 7], x[:, 8])
        for j in range(n):
            if k < len(seqs[j]):
                records[j].append(f"{float(u[j])!r} {int(batch.out['plausibility'][j])} "
                                  f"{int(batch.out['monitor_flags'][j])}\n")
    h = hashlib.sha256()
    for rec in records:
        h.update("".join(rec).encode())
    return h.hexdigest()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a tenth of the random sequences")
    args = parser.parse_args(argv)
    seqs = sequences(args.quick)
    print(f"sequences {len(seqs)} rows {sum(len(s) for s in seqs)}")
    state, rows, py_lines = python_rows(seqs)
    print(f"python-state  {state}")
    print(f"python-rows   {rows}")
    c = c_rows(seqs)
    if c is None:
        print("c-rows        (no gcc)")
    else:
        bad = sum(p != q for p, q in zip(py_lines, c[1]))
        print(f"c-rows        {c[0]}  ({bad} sequences differ from Python)")
    print(f"python-cycle  {python_cycle(seqs)}")
    cd = c_cycle(seqs)
    print(f"c-cycle       {cd if cd is not None else '(no cffi build)'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
