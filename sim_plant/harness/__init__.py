"""Running nodes together and judging what happened.

* ``launch``: every node's entry point and command line, built from typed settings.
* ``processes``: starting, supervising and stopping child processes (fresh or forked).
* ``hil``: a HIL run (plant, controller and logger on one bus).
* ``hil_report``, ``hil_steps``, ``hil_plot``: its outputs: the summary, the per-step table on
  the scenario's time, the decoded frames and the figures.
* ``replay``, ``replay_c``, ``replay_report``: a recorded candump log through the controller
  offline (Python node, and the C port's law on the same inputs), the verdict and the what-if
  of another calibration.
* ``faults``: the fault matrix, each row judged from the logged traffic (a package).
"""
