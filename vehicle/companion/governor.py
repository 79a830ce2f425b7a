"""The speed target the companion sends ArduPilot Rover for the speed the return commands (DESIGN §6.2: a return
never drives faster than the stretch was driven outbound).

Rover's GUIDED speed loop overshoots a velocity target after a start from rest: asked for 2.0 m/s, beside the
SITL's own physics (``--model rover``, its default tuning) it reached 2.45 m/s before settling at 2.00, on the way
out and on the way back alike. A return starts from rest where the owner's stop left the rover, so it came back
into the range 0.4 m/s faster than it was driven out, and the firmware's deceleration limit (measured: about
1 m/s/s) turned the excess into metres past the place the link came back. The steady speed is right (2.00 for
2.00), so no fixed scale would do: the companion foresees the overshoot from the autopilot's own estimate (the
speed and its rate of change, LEAD s ahead: the loop's lag) and takes GAIN times the foreseen excess off the
target (``Governor``). Measured beside the SITL's physics (tests/test_companion_stop.py): the return's peak
2.45 m/s for 2.0 without it; 2.21-2.28 with the excess taken off only once the speed had passed the command
(one run each: gain 2, gain 3, and with what it still gained; leading the target by at most 0.3 m/s from below:
2.26); 2.02-2.06 foreseen 0.5 s ahead from below (ten runs), against 2.01 driven out on that stretch. Foresight
from below cannot tell an overshoot coming from a loop that stops at its target (a stand-in that follows its
target at 3 m/s/s was held under the command, braking and driving in turn), so the governor drops it for the
autopilot that shows it needs none: a lowered target and the rover at once slowing, well below the command.
Where the speed is at or below the command the target is the command unchanged, so steady driving is as asked,
and slowing down (the approach speed, the brake) is only made firmer. What it cannot change is the firmware's
deceleration limit: from the outbound 2 m/s the stop after the first owner packet takes about 2 m whatever the
companion asks for (v^2 / 2a), plus the loop's reaction.
"""

from __future__ import annotations

from dataclasses import dataclass

GAIN = 3.0  # target lowered by this many m/s per m/s of excess
LEAD = 0.5  # s: the excess foreseen this far ahead (the speed loop's lag behind its target)
FELL = 0.2  # m/s: a rover this far below its command, and slowing, after a lowered target has a loop without lag
MOVING = 0.05  # m/s: a command below this is a stop or a turn on the spot, sent as it is


@dataclass
class Governor:
    """The speed targets for one autopilot (see the module docstring). ``foresee``: whether an excess is still
    foreseen from below the command. It is, until the autopilot shows its loop needs no foresight: a target
    lowered for an excess foreseen, and the rover at once slowing, FELL below the command (a loop that follows its
    target without lag, which foresight would hold under the command, braking and driving in turn; a dip of a few
    cm/s is the estimate's noise)."""

    foresee: bool = True
    lowered: bool = False  # the last target was lowered for an excess foreseen from below

    def target(self, command: float, measured: float, accel: float = 0.0) -> float:
        """The speed target (m/s, signed: negative is backward) for the vehicle's ``command`` when the autopilot's
        fresh estimate says the rover goes ``measured`` along its heading, its speed changing at ``accel`` (m/s/s).
        Never past zero: a governed target slows the rover, it never reverses it."""
        if abs(command) < MOVING:
            self.lowered = False
            return command
        sign = 1.0 if command > 0.0 else -1.0
        speed, gaining = measured * sign, accel * sign  # along the command: negative is the other way
        excess = speed - abs(command)
        if self.lowered and excess < -FELL and gaining < 0.0:
            self.foresee = False
        self.lowered = False
        if speed <= 0.0 or (excess < 0.0 and not self.foresee):
            return command
        foreseen = excess + max(0.0, gaining) * LEAD
        if foreseen <= 0.0:
            return command
        self.lowered = excess <= 0.0
        return sign * max(0.0, abs(command) - GAIN * foreseen)
