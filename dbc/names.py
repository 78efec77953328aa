"""The names the code uses for ``mrsteer.dbc``'s messages and signals, and the values the DBC
gives meaning to (the ``CtrlStatus_Cause`` bits, ``AuxSteerCmd_MeasCounter``'s NONE): defined
once here, checked against the DBC by ``tests/test_contract.py``.

The layouts themselves (bit positions, scaling, ranges, cycle times) are read from the DBC; only
the names are written down, because code has to say which message it means.
"""

from __future__ import annotations

# ------------------------------------------------------------------ messages

MSG_STEER = "MRS_DriverSteer"  # driver's front-wheel angle (vehicle -> controller)
MSG_YAW = "MRS_YawRate"  # yaw rate, the feedback signal (vehicle -> controller)
MSG_SPEED = "MRS_VehicleSpeed"  # speed over ground (vehicle -> controller)
MSG_REDUNDANT = "MRS_RedundantSensors"  # lateral acceleration, second steering channel, second speed (plausibility)
MSG_CMD = "MRS_AuxSteerCmd"  # the auxiliary steering command (controller -> actuator)
MSG_STATUS = "MRS_CtrlStatus"  # controller status and diagnostics
MSG_SYNC = "MRS_SecOCSync"  # SecOC freshness epoch (actuator -> controller)
MSG_BENCH = "MRS_BenchInject"  # test-bench disturbance and friction injection

SENSORS = (MSG_STEER, MSG_YAW, MSG_SPEED)  # the control law's sensor messages, in DBC order
REDUNDANT_SENSORS = (MSG_REDUNDANT,)  # the plausibility monitor's further sensor messages
VEHICLE_SENSORS = SENSORS + REDUNDANT_SENSORS  # every sensor message the vehicle sends (and signs)

# ------------------------------------------------------------------ signals

SIG_STEER_ANGLE = "DriverSteer_Angle"
SIG_YAW_RATE = "YawRate_YawRate"
SIG_YAW_RATE_2 = "YawRate_YawRate2"  # the yaw-rate sensor's second element
SIG_SPEED = "VehicleSpeed_Speed"
SIG_LAT_ACCEL = "RedundantSensors_LatAccel"
SIG_STEER_ANGLE_2 = "RedundantSensors_SteerAngle"
SIG_SPEED_2 = "RedundantSensors_Speed2"  # the second, independent speed
SIG_CMD_STATE = "AuxSteerCmd_State"
SIG_CMD_ANGLE = "AuxSteerCmd_Angle"
SIG_CMD_MEAS = "AuxSteerCmd_MeasCounter"
SIG_STATUS_STATE = "CtrlStatus_State"
SIG_STATUS_FLAGS = "CtrlStatus_InputFlags"
SIG_STATUS_CAUSE = "CtrlStatus_Cause"
SIG_STATUS_PLAUS = "CtrlStatus_Plausibility"
SIG_STATUS_REJECTED = "CtrlStatus_Rejected"
SIG_STATUS_OVERRUNS = "CtrlStatus_Overruns"
SIG_STATUS_LATENESS = "CtrlStatus_MaxLateness"
SIG_BENCH_YAW_MOMENT = "BenchInject_YawMoment"
SIG_BENCH_MU = "BenchInject_Mu"

# The signal each sensor message carries its measurement in.
SENSOR_SIGNAL = {MSG_STEER: SIG_STEER_ANGLE, MSG_YAW: SIG_YAW_RATE, MSG_SPEED: SIG_SPEED}

# ------------------------------------------------------------------ values

# CtrlStatus_Cause bits (the DBC's comment on the signal says what each means).
CAUSE_STEER_MISSING = 0x01
CAUSE_YAW_MISSING = 0x02
CAUSE_SPEED_MISSING = 0x04
CAUSE_E2E = 0x08
CAUSE_RANGE = 0x10
CAUSE_LOW_SPEED = 0x20
# SecOC on: no valid freshness sync (the actuator will not apply commands), or sensor frames failing their MAC
CAUSE_AUTH = 0x40

# The plausibility monitor (firmware_py.plausibility): its fault is this cause bit, and which check
# tripped is in CtrlStatus_Plausibility.
CAUSE_PLAUSIBILITY = 0x80

# CtrlStatus_Plausibility bits.
PLAUS_YAW = 0x01  # yaw rate (or the speed scheduling its model) implausible: see the DBC's comment
PLAUS_STEER = 0x02  # the two steering-angle channels disagree, or one is frozen
# a redundant input missing (fewer checks, authority limited to the panic window), or the monitor's
# OUTSIDE_MODEL (a_y or the car disagrees with a confirmed yaw rate: the controller fades its command)
PLAUS_DEGRADED = 0x04

MEAS_NONE = 15  # AuxSteerCmd_MeasCounter when the command answers no measurement (the DBC's "NONE")
