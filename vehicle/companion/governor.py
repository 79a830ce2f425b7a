"""The speed target the companion sends ArduPilot Rover for the speed the return commands (DESIGN §6.2: a return
never drives faster than the stretch was driven outbound).

Rover's GUIDED speed loop overshoots a velocity target after a start from rest: asked for 2.0 m/s, beside the
SITL's own physics (``--model rover``, its default tuning) it reached 2.45 m/s before settling at 2.00, on the way
out and on the way back alike. A return starts from rest where the owner's stop left the rover, so it came back
into the range 0.4 m/s faster than it was driven out, and the firmware's deceleration limit (measured: about
1 m/s/s) turned the excess into metres past the place the link came back. The steady speed is right (2.00 for
2.00), so no fixed scale would do: the companion foresees the overshoot from the autopilot's own estimate (the
speed and its rate of change, LEAD s ahead: the loop's lag) and takes GAIN times the foreseen excess off the
target (``governed``). Measured beside the SITL's physics (tests/test_companion_stop.py): the return's peak
2.45 m/s for 2.0 without it; 2.27-2.28 with the excess taken off only once it was there (gain 2 and 3); 2.07-2.10
foreseen 0.3 s ahead, 2.03-2.06 foreseen 0.5 s ahead (three runs each), against 2.01 driven out on that stretch.
Where the speed is at or below the command the target is the command unchanged, so steady driving is as asked,
and slowing down (the approach speed, the brake) is only made firmer. What it cannot change is the firmware's
deceleration limit: from the outbound 2 m/s the stop after the first owner packet takes about 2 m whatever the
companion asks for (v^2 / 2a), plus the loop's reaction.
"""

from __future__ import annotations

import math

GAIN = 3.0  # target lowered by this many m/s per m/s of measured excess
LEAD = 0.5  # s: the excess foreseen this far ahead (the speed loop's lag behind its target)
MOVING = 0.05  # m/s: a command below this is a stop or a turn on the spot, sent as it is


def governed(command: float, measured: float, accel: float = 0.0, gain: float = GAIN, lead: float = LEAD) -> float:
    """The speed target (m/s, signed: negative is backward) for the vehicle's ``command`` when the autopilot's fresh
    estimate says the rover goes ``measured`` along its heading, its speed changing at ``accel``: the excess is the
    one ``lead`` s ahead. Never past zero: a governed target slows the rover, it never reverses it."""
    if abs(command) < MOVING or measured * command <= 0.0:
        return command
    ahead = measured + accel * lead
    if ahead * command <= 0.0:
        return command
    excess = abs(ahead) - abs(command)
    if excess <= 0.0:
        return command
    return math.copysign(max(0.0, abs(command) - gain * excess), command)
