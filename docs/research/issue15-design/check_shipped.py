"""Scratch: reproduce the issue's figures for the shipped law (validates reflib)."""
import reflib as R, designs as D
for ideal_sensor, tau_a, label in ((True, 0.0, "ideal"), (True, 0.02, "act20"), (False, 0.0, "filter"), (False, 0.02, "reference")):
    R.set_sensor(ideal_sensor)
    c5 = D.shipped(5.0); c10 = D.shipped(10.0)
    rad = R.radius(R.closed_loop(5.0, 1.0, R.M_NOM, c5, tau_a=tau_a)[0])
    pk = R.peak_yaw(10.0, c10) if tau_a == 0 else None
    print(label, "radius@5", round(rad, 4))
R.set_sensor(True)
import math
c10 = D.shipped(10.0)
r,u,p = R.simulate(10,1,R.M_NOM,c10,4000,750,tau_a=1e-9)
print("ideal peak", r.max())
r,u,p = R.simulate(10,1,R.M_NOM,c10,4000,750,tau_a=0.02)
print("act20 peak", r.max())
print("ideal margins@5", R.margins(5,1,R.M_NOM,D.shipped(5.0)) if False else "")
R.set_sensor(False)
