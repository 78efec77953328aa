"""The sensors' noise streams of a batch: each row's own seeded stream per channel, drawn as
the scalar ``sensors.Sensors`` draws it (one standard normal per step), a block of steps at a
time.

Row i's stream of a channel is ``SeedSequence(seed_i, spawn_key=(child,))`` (``Sensors.reset``'s
child for the channel) through ``PCG64``: ``at(k)`` is every row's k-th draw, times the channel's
sigma.  The generators fill each row's contiguous row of a (rows, block) array (the generator's
per-call cost paid once a block); a channel read every step is then copied, scaled, into a
(block, rows) array in tiles that stay in cache, so that a step reads one contiguous row (a
strided column costs about 7 ns an element against 1 when contiguous).  Only the steps the run
has are drawn (a stream's draws after its last step change nothing before it).
"""

from __future__ import annotations

import numpy as np

_INIT_A, _MULT_A, _INIT_B, _MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R, _XSHIFT, _M32 = 0xCA01F9DD, 0x4973F715, 16, 0xFFFFFFFF
_PCG_MULT = (2549297995355413924 << 64) + 4865540595714422341
_M128 = (1 << 128) - 1


class _Hash:
    """``SeedSequence``'s hashmix over uint32 arrays; its constant advances as the scalar's."""

    def __init__(self, c: int) -> None:
        self.c = c

    def mix(self, value: np.ndarray) -> np.ndarray:
        v = value ^ np.uint32(self.c)
        self.c = (self.c * _MULT_A) & _M32
        v = v * np.uint32(self.c)
        return v ^ (v >> np.uint32(_XSHIFT))


def _mix(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    r = np.uint32(_MIX_L) * x - np.uint32(_MIX_R) * y
    return r ^ (r >> np.uint32(_XSHIFT))


def pcg64_states(seeds: np.ndarray, child: int | np.ndarray) -> list[tuple[int, int]]:
    """(state, inc) of ``PCG64(SeedSequence(seed, spawn_key=(child,)))`` per seed (int64, >= 0;
    ``child`` one for all, or one per seed):
    numpy's ``SeedSequence`` (pool of 4 words, the seed's words padded to it, the spawn key
    after) and ``pcg64_set_seed``, for all seeds at once."""
    seeds = np.asarray(seeds)
    if seeds.dtype.kind not in "iu" or seeds.size and (seeds.min() < 0 or seeds.max() > np.iinfo(np.int64).max):
        raise ValueError("noise seeds must be integers in [0, 2**63)")
    u = seeds.astype(np.uint64)
    lo = (u & np.uint64(_M32)).astype(np.uint32)
    hi = (u >> np.uint64(32)).astype(np.uint32)
    zero = np.zeros_like(lo)
    entropy = [lo, hi, zero, zero, np.full_like(lo, child)]  # the seed's words padded to the pool, the spawn key
    h = _Hash(_INIT_A)
    with np.errstate(over="ignore"):
        pool = [h.mix(e) for e in entropy[:4]]
        for i_src in range(4):
            for i_dst in range(4):
                if i_src != i_dst:
                    pool[i_dst] = _mix(pool[i_dst], h.mix(pool[i_src]))
        for i_dst in range(4):
            pool[i_dst] = _mix(pool[i_dst], h.mix(entropy[4]))
        c = _INIT_B
        words = []
        for i in range(8):
            v = pool[i % 4] ^ np.uint32(c)
            c = (c * _MULT_B) & _M32
            v = v * np.uint32(c)
            words.append(v ^ (v >> np.uint32(_XSHIFT)))
    w = [x.astype(np.uint64) for x in words]
    val = [(w[2 * i] | (w[2 * i + 1] << np.uint64(32))).tolist() for i in range(4)]
    out = []
    for s0, s1, i0, i1 in zip(*val):
        init_state, init_seq = (s0 << 64) | s1, (i0 << 64) | i1
        inc = ((init_seq << 1) | 1) & _M128
        # pcg_setseq_128_srandom_r: a step from state 0 (0 * mult + inc), the initial state added, a step
        out.append((((inc + init_state) * _PCG_MULT + inc) & _M128, inc))
    return out


#: Steps drawn per generator call.
BLOCK = 1024
#: A dense channel's draws are copied, scaled, into a (TILE, rows) array TILE steps at a time,
#: ROWS rows per copy (each copy's source and target a few hundred KiB: they stay in cache).
TILE, ROWS = 64, 256


class NoiseStream:
    """One channel's noise for every row: ``at(k)`` is ``scale`` times each row's k-th standard
    normal (k never decreasing between calls; a skipped block is drawn too, so the streams
    stay in step).  ``dense``: the channel is read at most steps (the transposed copy pays);
    else a step's draws are read as a strided column."""

    def __init__(self, seeds: np.ndarray, child: int | np.ndarray, scale: np.ndarray | float, steps: int | None = None,
                 dense: bool = True) -> None:
        self._bits = np.random.PCG64(0)  # its state is each row's in turn
        self._gen = np.random.Generator(self._bits)  # default_rng's stream without its dispatch
        self._states = [{"bit_generator": "PCG64", "state": {"state": st, "inc": inc}, "has_uint32": 0, "uinteger": 0}
                        for st, inc in pcg64_states(seeds, child)]
        self.scale, self.steps = scale, steps
        self._scale_rows = np.broadcast_to(np.asarray(scale, dtype=float), seeds.shape)
        self._raw = np.empty((seeds.size, BLOCK))
        self._rows = np.empty((TILE, seeds.size)) if dense else None
        self._block = self._tile = -1
        self._drawn = 0  # the steps of the block drawn

    def at(self, k: int) -> np.ndarray:
        block = k // BLOCK
        while self._block < block:
            self._draw(self._block + 1)
        j = k % BLOCK
        if self._rows is None:
            return self.scale * self._raw[:, j]
        tile = j // TILE
        if tile != self._tile:
            self._transpose(tile)
        return self._rows[j % TILE]

    def _draw(self, block: int) -> None:
        m = BLOCK if self.steps is None else max(1, min(BLOCK, self.steps - block * BLOCK))
        bits, normal, states = self._bits, self._gen.standard_normal, self._states
        for i, row in enumerate(self._raw):
            bits.state = states[i]
            normal(out=row[:m])
            states[i] = bits.state
        self._block, self._tile, self._drawn = block, -1, m

    def _transpose(self, tile: int) -> None:
        """Steps ``tile * TILE`` on of the block, scaled, one contiguous row per step."""
        a = tile * TILE
        b = min(self._drawn, a + TILE)
        rows, scale = self._rows, self._scale_rows
        for r0 in range(0, rows.shape[1], ROWS):
            r1 = r0 + ROWS
            np.multiply(scale[r0:r1], self._raw[r0:r1, a:b].T, out=rows[:b - a, r0:r1])
        self._tile = tile
