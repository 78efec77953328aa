"""Bus processes other than the controller, and the log they share.

* ``plant``: the simulated car, its sensors and the auxiliary actuator on a bus (``mrsteer plant``).
* ``logger``: writes every frame on a bus as a candump log.
* ``fault_bridge``: forwards frames between a vehicle bus and a controller bus, injecting faults
  (``mrsteer faults bridge``).
* ``candump_log``: the candump ``-L`` log format, written by the logger and read by the reports.
"""
