"""Analysis with no bus and no processes.

* ``closed_loop``: the continuous reference (eq. 8) and the firmware's own ``step()`` against
  the discretised plant; loop poles.
* ``experiments``: the disturbance, steering and threshold experiments behind ``mrsteer sim``.
* ``margins``, ``tuning``, ``sweep``: the discrete design over the operating envelope.
* ``paper``, ``figures``: the paper's Figures 8-10 and their comparison table.
* ``vectors``: the golden vectors the C port is checked against.
"""
