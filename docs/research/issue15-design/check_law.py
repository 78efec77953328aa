"""Scratch: the scalar Law equals the state-space law in closed loop (saturated run), and
its Butterworth equals scipy's."""
import math, numpy as np, reflib as R, scheduled as S
from scipy import signal
b = S.butterworth2(30.0, R.TS)
print("butter max diff", max(abs(x - y) for x, y in zip(b, list(R.BUT_B) + list(R.BUT_A[1:]))))
v = 10.0
r_ss, u_ss, _ = R.simulate(v, 1, R.M_NOM, S.law_ss(v), 6500.0, 1000)
# same loop, scalar law
phi, gd, gm = R.plant(v, 1, R.M_NOM); a = math.exp(-R.TS / R.TAU_A)
law = S.Law(); x = np.zeros(2); p = 0.0; xf = np.zeros(2); us = []
Af, Bf, Cf, Df = R.SENSOR.A, R.SENSOR.B[:, 0], R.SENSOR.C[0], R.SENSOR.D[0, 0]
for k in range(1000):
    mf = Cf @ xf + Df * x[1]; xf = Af @ xf + Bf * x[1]
    u = law.step(0.0, mf, v); us.append(u)
    x = phi @ x + gd * p + gm * 6500.0; p = a * p + (1 - a) * u
print("scalar vs ss max |du|", np.max(np.abs(np.array(us) - u_ss)), "saturated:", np.max(np.abs(us)) >= R.U_MAX)
