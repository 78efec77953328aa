"""Scratch: every constraint's figure at one speed (over the mu x mass grid) for a builder."""
from __future__ import annotations
import math
import numpy as np
import reflib as R

MUS = tuple(np.linspace(0.1, 1.0, 10))
MASSES = (1296.0, 1548.0, 1800.0)
import os
SAT_SPEEDS = tuple(float(s) for s in os.environ.get("SAT_SPEEDS", "10,20,40").split(","))


def at_speed(v, ctrl, mus=MUS, masses=MASSES, with_sat=True, with_peak=True, fast=False):
    """Worst figures at speed v. radius_* < 1 means stable under that perturbation."""
    w = {"gm": math.inf, "pm": math.inf, "noise": 0.0, "nominal": 0.0, "gain": 0.0, "phase": 0.0,
         "delay": 0.0, "tau_a": 0.0}
    where = {}
    for mu in mus:
        for m in masses:
            ps = R.perturbed_stable(v, mu, m, ctrl)
            for key, val in ps.items():
                if val > w[key]:
                    w[key], where[key] = val, (v, round(mu, 2), m)
            if ps["nominal"] >= 1.0:
                continue
            gm, pm = R.margins(v, mu, m, ctrl)
            if gm < w["gm"]:
                w["gm"], where["gm"] = gm, (v, round(mu, 2), m)
            if pm < w["pm"]:
                w["pm"], where["pm"] = pm, (v, round(mu, 2), m)
            nz = R.noise_rms_deg(v, mu, m, ctrl)
            if nz > w["noise"]:
                w["noise"], where["noise"] = nz, (v, round(mu, 2), m)
    if with_peak and w["nominal"] < 1:
        w["peak"] = R.peak_yaw(v, ctrl)
    if with_sat and v in SAT_SPEEDS and w["nominal"] < 1:
        w["sat"] = R.sat_threshold(v, ctrl, lo=3000.0, hi=12000.0, tol=5.0)
    w["where"] = where
    return w


def violations(w) -> float:
    """Sum of normalised constraint violations (0 when every constraint holds)."""
    pen = 0.0
    for key in ("nominal", "gain", "phase", "delay", "tau_a"):
        pen += max(0.0, w[key] - 0.99999) * 100
    pen += max(0.0, 6.0 - w["gm"]) / 6.0 if math.isfinite(w["gm"]) or w["gm"] == math.inf else 1.0
    pen += max(0.0, 45.0 - w["pm"]) / 45.0
    pen += max(0.0, w["noise"] - 0.15) / 0.15
    if "sat" in w:
        pen += max(0.0, 6119.0 - w["sat"]) / 6119.0
    return pen
