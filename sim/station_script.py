"""What every scripted operator is, whatever it flies (returnlink's vehicle through ``gcs``, the ArduPilot firmware
alone, with its applet or with the companion, PX4 alone or with the companion): a person with a route out and a
way home, who drives toward one waypoint at a time and learns from a lost link.

``ScriptedStation`` is the one root of the scripted operators (``sim.operator.Operator``,
``sim.firmware.operator.FirmwareOperator`` and what builds on it): the two legs, the phase of the script, the
waypoint being driven toward, the one the link was lost on the way to, how many times each place cost the link,
and the log. A place the link died on the way to is tried again, but after ``attempts`` losses on the way there
the operator gives that place up and goes on with the rest of its route. Without that, a script would drive back
into the same dead zone for as long as the scenario lasts, and every loss the run counts would be the script's, not
the vehicle's (``attempts = 1000`` keeps that stubborn operator). After a return, a person picks the way home up
where the robot now is (``Leg.join``); ``rejoin`` False drives every waypoint of it as written.

How each one talks to what it flies (a ground-station library, or MAVLink frames of its own) and what it reads as
a loss and a return is its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

WAYPOINT_RADIUS = 1.5  # m: a waypoint counts as reached this close


@dataclass
class Leg:
    points: tuple[tuple[float, float, float], ...]
    index: int = 0

    @property
    def done(self) -> bool:
        return self.index >= len(self.points)

    def join(self, x: float, y: float) -> None:
        """Pick the route up where a person would, from (x, y): at the start of the leg the robot is on (its
        projection falls inside the leg, within WAYPOINT_RADIUS of it, nearer it than the next waypoint), never
        behind the waypoint already reached; off every leg (in a room beside a doorway) it drives to the next
        waypoint, as the route was written. An operator whose robot the return brought home past the first
        waypoint of the way out drives on home, not back into the dead zone to touch that waypoint first."""
        if self.done:
            return
        wx, wy = self.points[self.index][:2]
        best, best_d = self.index, math.hypot(x - wx, y - wy)
        for k in range(max(self.index, 1), len(self.points)):
            (ax, ay), (bx, by) = self.points[k - 1][:2], self.points[k][:2]
            dx, dy = bx - ax, by - ay
            L2 = dx * dx + dy * dy
            u = ((x - ax) * dx + (y - ay) * dy) / L2 if L2 > 0 else -1.0
            if 0.0 < u < 1.0:
                d = math.hypot(x - ax - u * dx, y - ay - u * dy)
                if d < best_d and d < WAYPOINT_RADIUS:
                    best, best_d = k, d
        self.index = best


class ScriptedStation:
    """The root of every scripted operator (see the module docstring)."""

    def __init__(self, route, resume_route, attempts: int = 2, rejoin: bool = True) -> None:
        self.leg = Leg(tuple(route))
        self.resume = Leg(tuple(resume_route))
        self.attempts = attempts
        self.rejoin = rejoin  # False: a stubborn operator that drives every waypoint of its way home
        self.phase = "connect"
        self.heading_to: tuple[float, float] | None = None  # the waypoint being driven toward
        # the one being driven toward at the latest sign of a loss; it counts once the robot is back
        self.cut_off: tuple[float, float] | None = None
        self.losses: dict[tuple[float, float], int] = {}  # waypoint -> links lost on the way there
        self.log: list[tuple[float, str]] = []

    def _say(self, t: float, text: str) -> None:
        self.log.append((t, text))

    def _lost_on_the_way(self) -> None:
        """A sign of a loss (the picture froze, the robot said it lost us, a return began): it names the place
        being driven toward, or keeps the one named before."""
        self.cut_off = self.heading_to or self.cut_off

    def _count_loss(self) -> None:
        """The robot came back without the link: the place it was cut off on the way to counts one loss, once."""
        if self.cut_off is not None:
            self.losses[self.cut_off] = self.losses.get(self.cut_off, 0) + 1
            self.cut_off = None

    def _given_up(self, place: tuple[float, float]) -> bool:
        """Whether the link died on the way to ``place`` often enough to give it up."""
        return self.losses.get(place, 0) >= self.attempts

    def _pick_up_way_home(self, position: tuple[float, float] | None) -> None:
        """After a return, on the way home: from where the robot now is, unless this operator drives it as written."""
        if self.rejoin and self.phase == "resuming" and position is not None:
            self.resume.join(*position)
