"""The auxiliary steering actuator: what it applies each plant step, from the newest valid
command it was given.

It follows a fresh command (clamped to its range, and to its own slew rate when it has one);
when no valid command came for ``cmd_timeout`` it fades to zero at a bounded rate, and once
commands come back it slews to them at the same rate rather than jump.  It knows nothing of the
bus: the plant node (``sim_plant.nodes.plant``) tells it when a valid command arrived, and what
the controller's last ``MRS_CtrlStatus`` said about its inputs.

It bounds the command's authority a second time, independently of the controller (issue 18,
item 3; the first is where the command leaves the controller): the same ``firmware_py.authority``
limiter, at the actuator's own step, on the plausibility bits of the controller's status frame.
A status older than ``STATUS_STALE_S`` counts as DEGRADED: an intervention then ends at the
panic window, as it does when the controller says it cannot check its inputs.  That is also all
this outer bound does on the controller's OUTSIDE_MODEL (DEGRADED on the bus, which does not
tell it from a missing input's; the controller fades that command itself).  It reads the status's
plausibility bits, not the controller's state (``AuxSteerCmd_State``: STARTING, DEGRADED and the
rest are for the people and the logs reading the bus; the campaigns' model of this plant,
``sim_plant.campaign.reference``, reads the same bits at the same status cycle).  A plausibility
fault latches here as it does in the controller: until the actuator restarts, the command stays
faded whatever arrives after it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_py import authority as au
from firmware_py.calibration import AUX_LIMIT
from firmware_py.plausibility import PLAUS_DEGRADED, PLAUS_FAULT

CMD_TIMEOUT_S = 0.02  # s without a valid command before the actuator fades to zero
FADE_RATE_RAD_S = math.radians(30.0)  # rad/s of the fade to zero, and of the slew back after it
RATE_LIMIT_RAD_S = 0.0  # rad/s of the actuator's own slew limit; 0: it follows the command at once
STATUS_STALE_S = 0.3  # s without MRS_CtrlStatus (three of its cycles) before the inputs count as unchecked


@dataclass(frozen=True)
class ActuatorConfig:
    cmd_timeout: float = CMD_TIMEOUT_S
    fade_rate: float = FADE_RATE_RAD_S
    rate_limit: float = RATE_LIMIT_RAD_S
    limit: float = AUX_LIMIT  # +- rad of front-wheel angle (paper, sec. 4.1: +-3 deg)


class Actuator:
    """The actuator stepped at the plant's period ``ts``: ``command_received()`` when a valid
    command arrives, ``apply(command)`` for the angle over this step, ``tick()`` once per step."""

    def __init__(self, config: ActuatorConfig, ts: float) -> None:
        self.config = config
        self.limit = config.limit
        self.timeout_steps = max(1, int(math.ceil(config.cmd_timeout / ts)))
        self.fade_step = config.fade_rate * ts
        self.slew_step = config.rate_limit * ts  # 0: the actuator follows the command at once
        self.applied = 0.0  # rad, the angle being applied
        self.cmd_age = 0  # steps since the last valid command
        self.recovering = False  # slewing back to the command after a timeout fade
        self.timeouts = 0  # times the commands went stale
        self.authority_coeffs = au.configure_authority(au.AuthorityConfig(ts=ts, u_max=config.limit))
        self.authority = au.AuthorityState()
        self.authority_steps = 0  # steps in which the authority limiter changed the command
        self.plausibility = PLAUS_DEGRADED  # the controller's last CtrlStatus_Plausibility
        self.fault_latched = 0  # PLAUS_FAULT bits any status has shown
        self.status_stale_steps = max(1, int(math.ceil(STATUS_STALE_S / ts)))
        self.status_age = self.status_stale_steps + 1  # no status yet

    @property
    def fresh(self) -> bool:
        """A valid command came within the timeout."""
        return self.cmd_age <= self.timeout_steps

    def command_received(self) -> None:
        self.cmd_age = 0

    def status_received(self, plausibility: int) -> None:
        """The controller's ``CtrlStatus_Plausibility`` bits, from a valid status frame."""
        self.plausibility = plausibility
        self.fault_latched |= plausibility & PLAUS_FAULT
        self.status_age = 0

    def tick(self) -> None:
        self.cmd_age += 1
        self.status_age += 1

    def apply(self, command: float | None) -> float:
        """What the actuator applies this step (also kept in ``applied``): the command (clamped
        to its range) while commands are fresh, otherwise a bounded-rate fade to zero.  After a
        fade it slews back to the command at the same bounded rate rather than jump to it."""
        self.applied = self._next(command)
        return self.applied

    def _next(self, command: float | None) -> float:
        a = self.applied
        if command is not None and self.fresh:
            bits = self.plausibility if self.status_age <= self.status_stale_steps else PLAUS_DEGRADED
            bits |= self.fault_latched
            command = au.authority_step(self.authority_coeffs, self.authority, command, bits)
            if self.authority.flags:
                self.authority_steps += 1
            target = max(-self.limit, min(self.limit, command))
            if self.slew_step > 0.0:  # the actuator's own rate limit, whatever arrives
                target = max(a - self.slew_step, min(a + self.slew_step, target))
            if not self.recovering or abs(target - a) <= self.fade_step:
                self.recovering = False
                return target
            return a + self.fade_step if target > a else a - self.fade_step
        if self.cmd_age == self.timeout_steps + 1:
            self.timeouts += 1
        self.recovering = True
        return a - self.fade_step if a > self.fade_step else a + self.fade_step if a < -self.fade_step else 0.0
