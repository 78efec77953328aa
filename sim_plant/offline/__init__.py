"""Analysis with no bus and no processes.

* ``closed_loop``: the continuous reference (eq. 8) and the firmware's own ``step()`` against
  the discretised plant (with the actuator and sensor models in the loop).
* ``loop_plant``, ``discrete_loop``: the sampled plant (car, actuator, yaw-rate filter) and the
  closed loop's state matrix on it: poles, delay and noise inputs.
* ``constraints``: issue 15's design constraints (extra delay, actuator time constant, command
  noise, applied-angle saturation threshold) per operating point.
* ``experiments``: the disturbance, steering and threshold experiments behind ``mrsteer sim``.
* ``margins``, ``tuning``, ``sweep``: the discrete design over the operating envelope.
* ``paper``, ``figures``: the paper's Figures 8-10 and their comparison table.
* ``vectors``: the golden vectors the C port is checked against.
* ``plausibility_runs``: the closed loop with the plausibility monitor and the authority limiter
  (detection times and false-alarm margins of ``firmware_py.plausibility``).
"""
