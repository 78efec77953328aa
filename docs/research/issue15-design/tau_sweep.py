"""Scratch: stability for actuator time constants 10..40 ms (fine) at every speed/mu/mass corner."""
import numpy as np, reflib as R, scheduled as S
worst = (0, None)
for v in [5.0 + 2.5 * i for i in range(19)]:
    c = S.law_ss(v)
    for mu in (0.1, 0.4, 0.7, 1.0):
        for m in (1296.0, 1800.0):
            for ta in np.linspace(0.010, 0.040, 13):
                r = R.radius(R.closed_loop(v, mu, m, c, tau_a=ta)[0])
                if r > worst[0]:
                    worst = (r, (v, mu, m, round(ta, 4)))
            for ta in (0.010, 0.020, 0.040):  # extra delay and slow/fast actuator together
                r = R.radius(R.closed_loop(v, mu, m, c, tau_a=ta, extra_delay=1)[0])
                if r > worst[0]:
                    worst = (r, (v, mu, m, ta, "with extra delay"))
print("worst pole radius over tau_a 10..40 ms (and with the extra sample):", worst)
