"""Shared helpers for the test suite."""

from __future__ import annotations

import os
import tempfile

import numpy as np
import pytest
from numpy.polynomial import polynomial as P

# Every fallback-bus socket the tests create lives in a private directory of this run, so
# parallel runs and a user's own brokers never meet.
os.environ["MRSTEER_BUS_DIR"] = tempfile.mkdtemp(prefix="mrsteer-bus-test-")


def polymul(*polys: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """Product of polynomials given highest power first (scipy.signal convention)."""
    out = np.array([1.0])
    for p in polys:
        out = np.polymul(out, np.asarray(p, dtype=float))
    return out


def polyadd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.polyadd(np.asarray(a, float), np.asarray(b, float))


@pytest.fixture
def channel(request: pytest.FixtureRequest) -> str:
    """A fresh fallback-bus channel name for one test."""
    return "t-" + "".join(ch if ch.isalnum() else "-" for ch in request.node.name)[-60:]


__all__ = ["polymul", "polyadd", "P"]
