"""Scratch: Nelder-Mead on the S1 structure at one speed, every constraint at that speed."""
import sys, math, json
import numpy as np
from scipy.optimize import minimize
import reflib as R, designs as D, evalpt as E

import os; PEN = float(os.environ.get("PEN", "0.2"))
v = float(sys.argv[1]); order = int(sys.argv[2]); nc = int(sys.argv[3])
x0 = [math.log(20), math.log(0.008), math.log(0.08)] + [0.5] * nc
best = {"f": 1e9}

def unpack(x):
    k, tq, tn = math.exp(x[0]), math.exp(x[1]), math.exp(x[2])
    return k, tq, tn, tuple(x[3:])

def f(x):
    k, tq, tn, c = unpack(x)
    if k > 60 or tq < 2e-4 or tq > 0.1 or tn > 1:
        return 10.0
    try:
        w = E.at_speed(v, D.s1(v, k, tq, tn, order, c))
    except Exception as e:
        return 10.0
    if w["nominal"] >= 1:
        return 10.0
    val = w["peak"] + PEN * E.violations(w)
    if val < best["f"]:
        best.update(f=val, x=[k, tq, tn, *c], w={kk: vv for kk, vv in w.items() if kk != "where"})
        print(round(val, 5), [round(p, 5) for p in best["x"]], {kk: round(vv, 4) for kk, vv in best["w"].items()}, flush=True)
    return val

if len(sys.argv) > 4:
    x0 = json.loads(sys.argv[4])
res = minimize(f, x0, method="Nelder-Mead", options={"maxfev": int(sys.argv[5]) if len(sys.argv) > 5 else 250, "xatol": 1e-3, "fatol": 1e-6, "initial_simplex": None})
print("BEST", json.dumps(best["x"]), best["w"])
