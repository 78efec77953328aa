"""Running nodes together and judging what happened.

* ``launch``: every node's entry point and command line, built from typed settings.
* ``processes``: starting, supervising and stopping child processes (fresh or forked).
* ``hil``: a HIL run (plant, controller and logger on one bus).
* ``hil_report``, ``hil_steps``, ``hil_plot``: its outputs: the summary, the per-step table on
  the scenario's time, the decoded frames and the figures.
* ``faults``: the fault matrix, each row judged from the logged traffic (a package).
"""
