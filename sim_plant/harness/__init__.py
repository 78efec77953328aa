"""Running nodes together and judging what happened.

* ``processes``: starting, supervising and stopping child processes.
* ``hil``: a HIL run (plant, controller and logger on one bus) and its outputs.
* ``faults``: the fault matrix, each row judged from the logged traffic.
"""
