"""Scratch: every constraint of issue 15 for the scheduled law over the whole envelope.

v on a 2.5 m/s grid from 5 to 50 (breakpoints and between them), mu 0.1..1 (10), m 1296,
1548, 1800; saturation threshold at 10/20/40 m/s; peak yaw rate after 4000 Nm at 10/20/40;
a Monte-Carlo check of the H2 noise figure at its worst point.  `--json` prints the points."""
import sys, json, math
import numpy as np
import reflib as R, scheduled as S, evalpt as E

speeds = [5.0 + 2.5 * i for i in range(19)]
worst = {"gm": (math.inf, None), "pm": (math.inf, None), "noise": (0.0, None)}
for key in ("nominal", "gain", "phase", "delay", "tau_a"):
    worst[key] = (0.0, None)
rows = []
for v in speeds:
    w = E.at_speed(v, S.law_ss(v), with_sat=v in (10.0, 20.0, 40.0), with_peak=v in (10.0, 20.0, 40.0))
    rows.append({k: (float(x) if isinstance(x, (float, np.floating)) else x) for k, x in w.items() if k != "where"} | {"v": v})
    for key in worst:
        better = (w[key] < worst[key][0]) if key in ("gm", "pm") else (w[key] > worst[key][0])
        if better:
            worst[key] = (float(w[key]), w["where"].get(key))
    print(v, {k: round(x, 4) for k, x in w.items() if k != "where"}, flush=True)
print("WORST", {k: (round(x, 4), wh) for k, (x, wh) in worst.items()})
# Monte-Carlo noise at the worst point
v, mu, m = worst["noise"][1]
rng = np.random.default_rng(1)
n = 200_000
noise = rng.normal(0.0, R.NOISE_SIGMA, n)
_, u, _ = R.simulate(v, mu, m, S.law_ss(v), 0.0, n, noise=noise)
mc = math.degrees(np.std(u[5000:]))
print("noise H2 %.4f deg, Monte-Carlo %.4f deg (%d samples) at" % (worst["noise"][0], mc, n - 5000), (v, mu, m))
if "--json" in sys.argv:
    print(json.dumps(rows))
