"""Everything that stands in for the car, and the harness that puts it on a bus with a controller.

* ``car``: the vehicle (the linear single-track model of eqs. 14/16, discretised exactly) and
  the scenarios it plays.
* ``offline``: analysis with no bus and no processes: closed-loop simulation, margins, tuning,
  sweeps, the paper's figures, golden vectors.
* ``judge``: the one judge of a sensor fault: the bound its error is judged against, the offset
  its check adds, when it left the bound, the yaw rate its command caused.
* ``nodes``: bus processes other than the controller: the plant, the bus logger, the fault bridge.
* ``harness``: running nodes together: process supervision, HIL runs, the fault matrix.
* ``campaign``: validation campaigns: thousands of sampled scenarios on the realistic car with
  the firmware's law, vectorised over the batch, chunked on Dask, results as Parquet.

``python -m sim_plant`` runs the plant node.
"""
