"""The samples of a campaign: sample i is a function of the campaign file and i alone.

* ``lhs``: a Latin hypercube over the drawn parameters (``scipy.stats.qmc.LatinHypercube``),
  generated whole from the campaign's seed; sample i is its row i, so any chunk, on any
  worker, in any order, and ``campaign export`` get the same values.
* ``random``: independent uniforms per sample from the numpy stream
  ``SeedSequence(seed, spawn_key=(i,))``, i.e. the i-th spawned child of the campaign's seed.

The unit coordinates u in [0, 1) are mapped to each parameter's distribution: uniform
lo + u (hi - lo), loguniform exp(log lo + u log(hi / lo)), choice the floor(u n)-th value.
Each sample's sensor-noise seed is ``params.noise_seed(seed, i)``.
"""

from __future__ import annotations

import math

import numpy as np

from sim_plant.campaign.params import INDEX, NOISE_SEED, SampleSet, noise_seed
from sim_plant.campaign.spec import Campaign


def unit_design(c: Campaign, rows: np.ndarray) -> np.ndarray:
    """The unit coordinates (len(rows), dimensions) of the samples ``rows``."""
    d = len(c.sampled)
    if d == 0:
        return np.zeros((rows.size, 0))
    if c.sampling == "lhs":
        # Here, not at the top: scipy.stats costs 1.5 s to import, and most importers of the
        # campaign package (report, export, the command line) never sample.
        from scipy.stats import qmc

        full = qmc.LatinHypercube(d=d, seed=np.random.default_rng(c.seed)).random(c.samples)
        return full[rows]
    out = np.empty((rows.size, d))
    for j, i in enumerate(rows.tolist()):
        out[j] = np.random.default_rng(np.random.SeedSequence(c.seed, spawn_key=(i,))).random(d)
    return out


def samples(c: Campaign, rows: np.ndarray, design: np.ndarray | None = None) -> SampleSet:
    """The SampleSet of the sample indices ``rows`` (``design``: their unit rows, if known)."""
    rows = np.asarray(rows, dtype=np.int64)
    if rows.size and (rows.min() < 0 or rows.max() >= c.samples):
        raise ValueError(f"sample index out of range: the campaign has {c.samples} samples (0..{c.samples - 1})")
    u = unit_design(c, rows) if design is None else design
    cols: dict[str, np.ndarray] = {}
    dims = {name: j for j, name in enumerate(c.sampled)}
    for name, dist in c.parameters.items():
        if dist.kind == "fixed":
            cols[name] = np.full(rows.size, dist.values[0])
            continue
        x = u[:, dims[name]]
        if dist.kind == "uniform":
            lo, hi = dist.values
            cols[name] = lo + x * (hi - lo)
        elif dist.kind == "loguniform":
            lo, hi = dist.values
            cols[name] = np.clip(np.exp(math.log(lo) + x * math.log(hi / lo)), lo, hi)
        else:
            values = np.asarray(dist.values)
            cols[name] = values[np.minimum((x * values.size).astype(np.int64), values.size - 1)]
    cols[INDEX] = rows
    cols[NOISE_SEED] = noise_seed(c.seed, rows)
    return SampleSet(cols)
