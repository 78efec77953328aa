"""Bus processes other than the controller.

* ``plant``: the simulated car, its sensors and the auxiliary actuator on a bus (``mrsteer plant``).
* ``logger``: writes every frame on a bus as a candump log.
* ``fault_bridge``: forwards frames between a vehicle bus and a controller bus, injecting faults.
"""
