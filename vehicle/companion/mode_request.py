"""A mode asked of the autopilot, followed until its HEARTBEAT shows it, asked again, or given up on.

An autopilot answers DO_SET_MODE with COMMAND_ACK and says its mode in its 1 Hz HEARTBEAT; either may be lost on a
radio, and PX4 refuses Offboard until its own check has seen the setpoint stream. So a request is sent again every
``mode_retry`` s, at most ``mode_tries`` times, and a refusal ends it only once the tries are spent where the
autopilot streams first (PX4) or at once where it does not (ArduPilot). Pure: the driver sends what this says.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion.observed import Observed
from vehicle.companion.rules import Rules


class Step(Enum):
    """What a mode request needs this tick."""

    NONE = "none"  # nothing asked, or still waiting for the answer
    DONE = "done"  # the autopilot is in the mode
    RESEND = "resend"  # not seen yet: ask again
    GAVE_UP = "gave up"  # refused, or the tries are spent


@dataclass
class ModeRequest:
    """The mode last asked for (``wanted``, None: none pending), when and how often it was sent, and the autopilot's
    refusal if it refused."""

    wanted: int | None = None
    asked_at: float = -math.inf
    tries: int = 0
    refused: str | None = None

    def ask(self, mode: int) -> None:
        """A new request for ``mode`` (not yet sent)."""
        self.wanted, self.tries, self.refused = mode, 0, None

    def sent(self, t: float) -> None:
        """The request went out at ``t``."""
        self.asked_at, self.tries = t, self.tries + 1

    def drop(self) -> None:
        self.wanted = None

    def step(self, t: float, seen: Observed, rules: Rules) -> Step:
        """Where the request stands at ``t`` by what the autopilot said (clears ``wanted`` when DONE)."""
        if self.wanted is None:
            return Step.NONE
        if seen.mode == self.wanted and (rules.lead is None or seen.mode_at >= self.asked_at):
            # (PX4: said after the request, so a mode it was leaving when asked does not count)
            self.wanted = None
            return Step.DONE
        if self.refused is not None or (t - self.asked_at >= rules.mode_retry and self.tries >= rules.mode_tries):
            return Step.GAVE_UP
        if t - self.asked_at >= rules.mode_retry:
            return Step.RESEND
        return Step.NONE

    def answered(self, m, t: float, seen: Observed, rules: Rules) -> None:
        """The autopilot's COMMAND_ACK to a DO_SET_MODE: accepted, the mode counts as said now (the next heartbeat
        shows it); refused, the request ends (PX4: once its tries are spent, see the module docstring)."""
        if self.wanted is None:
            return
        if m.result == apm.MAV_RESULT_ACCEPTED:
            seen.mode, seen.mode_at = self.wanted, t  # set before the answer left: the next heartbeat shows it
        elif m.result != apm.MAV_RESULT_IN_PROGRESS and not (rules.lead is not None and self.tries < rules.mode_tries):
            entry = apm.enums["MAV_RESULT"].get(m.result)
            self.refused = (f"the autopilot refused {rules.mode_name(self.wanted)} "
                            f"({entry.name.removeprefix('MAV_RESULT_') if entry else m.result})")
