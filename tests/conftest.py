"""Shared helpers for the test suite."""

from __future__ import annotations

import numpy as np
from numpy.polynomial import polynomial as P


def polymul(*polys: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """Product of polynomials given highest power first (scipy.signal convention)."""
    out = np.array([1.0])
    for p in polys:
        out = np.polymul(out, np.asarray(p, dtype=float))
    return out


def polyadd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.polyadd(np.asarray(a, float), np.asarray(b, float))


__all__ = ["polymul", "polyadd", "P"]
