"""The batch engine's noise streams against numpy's own seeding and the scalar sensors' draws."""

from __future__ import annotations

import numpy as np
import pytest

from sim_plant.campaign.noise import BLOCK, TILE, NoiseStream, pcg64_states


def test_initial_states_are_numpys_seed_sequence_and_pcg64_seeding() -> None:
    rng = np.random.default_rng(7)
    seeds = np.concatenate([rng.integers(0, 2**63 - 1, 300), rng.integers(0, 2**32, 50),
                            [0, 1, 2**32 - 1, 2**32, 2**63 - 1]])
    for child in (0, 1, 2, 4):
        for seed, (state, inc) in zip(seeds.tolist(), pcg64_states(seeds, child)):
            expected = np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(child,))).state["state"]
            assert (state, inc) == (expected["state"], expected["inc"]), (seed, child)


def test_negative_or_non_integer_seeds_are_refused() -> None:
    with pytest.raises(ValueError):
        pcg64_states(np.array([3, -1]), 0)
    with pytest.raises(ValueError):
        pcg64_states(np.array([1.5]), 0)


@pytest.mark.parametrize("dense", [True, False])
def test_each_step_is_the_rows_own_stream_scaled_across_blocks_and_tiles(dense: bool) -> None:
    """Row i at step k is scale_i times the k-th standard normal of the scalar sensor's stream
    (``default_rng(SeedSequence(seed).spawn(...)[child])``), read every step or skipping steps."""
    rng = np.random.default_rng(3)
    rows, steps = 300, BLOCK + 3 * TILE + 5  # a second, partial block
    seeds, scale = rng.integers(0, 2**62, rows), rng.uniform(0.1, 2.0, rows)
    expected = np.stack([scale[i] * np.random.default_rng(np.random.SeedSequence(int(seeds[i]), spawn_key=(2,)))
                         .standard_normal(steps) for i in range(rows)], axis=1)
    stream = NoiseStream(seeds, 2, scale, steps, dense=dense)
    read = range(steps) if dense else range(0, steps, 25)
    for k in read:
        assert np.array_equal(stream.at(k), expected[k]), k
