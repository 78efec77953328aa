"""The fault matrix (``mrsteer faults run``): every fault on a live bus, judged from the traffic.

Each row runs the plant (realtime, ``paper-fig9``: 4000 Nm at 0.5 s) and the controller as
separate processes on two fallback buses joined by the fault bridge (``fault_bridge.py``), with
a logger on each bus.  The bridge injects one fault in a window; the runner may kill or restart
the controller or the plant.  Every row is then judged from what was logged and reported:

* **safe** (every row): the applied angle (the plant's trace; the plant stands in for the
  actuator ECU and limits its own slew to 60°/s whatever arrives) never exceeds the ±3° limit
  nor that rate, so it never jumps; and the controller's own commands on the bus never step
  by more than its rate limit (40°/s, set for these runs) from one cycle to the next;
* **nothing lost** (every row): each logger logged every frame that was on its bus, counted by
  the bridge, which sees every frame of both buses;
* **alive** (every row but the controller-kill rows): the controller ran to the end and exited cleanly;
* row-specific: detection within the stated number of controller cycles (counted in commands
  on the bus, not in wall time), the cause in ``MRS_CtrlStatus``, recovery after the fault,
  rejected frames counted, the actuator's fade after a controller crash;
* the sensor rows (a wrong value in well-formed frames, issue 18): the plausibility fault
  within 300 ms of the error leaving the monitor's bound, cause 0x80, the command faded to zero
  at 6 deg/s, both latched; and in every no-fault row, no plausibility fault bit at all.  Beside
  these, a sensor row reports (does not judge) the yaw rate the command caused (``caused_yaw``).

Rows marked SecOC run controller and plant with a fresh random key (``$MRSTEER_SECOC_KEY``).  A
16-bit MAC lets a random guess through with probability 2^-16, so those rows allow up to
``MAC_LUCK`` lucky frames in a few hundred (the chance of more is below 1e-8) and report them.

The package, by concern: ``settings`` (the numbers, ``Setup``), ``rows`` (the matrix), ``run``
(running a row and the matrix), ``evidence`` and ``verdicts`` (reading a row's files; ``judge``
and its checks), ``verdicts_plausibility`` (the sensor rows' and the quiet monitor's checks), ``caused_yaw``
(the yaw rate a sensor row's command caused, from the plant's trace),
``cli`` (``mrsteer faults`` and its table).
"""

from sim_plant.harness.faults.cli import format_table, main
from sim_plant.harness.faults.verdicts import RowResult, faulted_after_bad_frames, judge
from sim_plant.harness.faults.rows import ROWS, SENSOR_ROWS, Row, plant_fault, secured_rows
from sim_plant.harness.faults.run import holds_files, run_matrix, run_row
from sim_plant.harness.faults.settings import (ACTUATOR_RATE, CALIBRATIONS, CMD_TIMEOUT, COUNTER_WINDOW, DURATION,
                                               E2E_FAIL_MAX, FLOOD_CAPACITY, FORGED_ANGLE, MAC_LUCK, PLANT_FADE,
                                               RATE_HZ, RATE_LIMIT, TIMEOUT_CYCLES, WINDOW, Setup)

__all__ = ["ACTUATOR_RATE", "CALIBRATIONS", "CMD_TIMEOUT", "COUNTER_WINDOW", "DURATION", "E2E_FAIL_MAX",
           "FLOOD_CAPACITY", "FORGED_ANGLE", "MAC_LUCK", "PLANT_FADE", "RATE_HZ", "RATE_LIMIT", "ROWS", "Row",
           "RowResult", "SENSOR_ROWS", "Setup", "TIMEOUT_CYCLES", "WINDOW", "faulted_after_bad_frames", "format_table",
           "holds_files", "judge", "main", "plant_fault", "run_matrix", "run_row", "secured_rows"]
