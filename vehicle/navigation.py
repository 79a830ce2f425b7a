"""Path following: a route in, forward speed and yaw rate out, for wheels and legs alike.

Pure pursuit with a speed-scaled lookahead, a monotone progress variable (so a route that passes near itself is
never short-circuited) and a slow-down for arcs tighter than the robot can turn at speed and for arrival. The
robot model's own limits (acceleration, turn rate, stride) are applied by whoever drives the actuators; the
follower only asks for what is sensible.

A return starts where the robot stopped, facing away from home: its route lies behind it. Swinging round on a
forward arc needs a turning circle the corridor it just drove may not have (a 5 m adit is narrower than a U-turn
at walking pace), so when the route lies behind, the follower drives it in reverse (a rover backs up, a quadruped
walks backward), retracing the swept path it came in by. The direction has hysteresis, so a route that runs
sideways does not make it dither; and whenever the heading error is large it turns in place before it drives,
never an arc with speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from link.parameters import default

if TYPE_CHECKING:
    from vehicle.params import Params

TURN_IN_PLACE = 0.6  # rad: heading error beyond which a robot turns before it drives (returns and teleop alike)


@dataclass(frozen=True)
class FollowerConfig:
    lookahead_min: float = 0.8
    lookahead_gain: float = 0.6  # s: lookahead grows with speed
    max_yaw_rate: float = 1.5  # rad/s
    arrive_radius: float = default("RTL_ARRIVE_R")
    turn_in_place: float = TURN_IN_PLACE
    reverse_beyond: float = math.radians(100.0)  # the route lies behind: drive it backward
    forward_within: float = math.radians(80.0)  # ... until it lies ahead again (hysteresis)
    can_reverse: bool = True

    @classmethod
    def from_params(cls, params: Params) -> FollowerConfig:
        """The follower a return drives with: the arrival radius is RTL_ARRIVE_R, the rest the robot's."""
        return cls(arrive_radius=params["RTL_ARRIVE_R"])


@dataclass(frozen=True)
class FollowCommand:
    speed: float
    yaw_rate: float
    progress: float  # arc length along the route already passed
    remaining: float  # arc length still to go
    arrived: bool
    reverse: bool = False  # driving backward; pass it back in on the next step


class Path:
    """A polyline with its cumulative arc length, precomputed once per (re)plan."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.asarray(points, dtype=float)
        seg = np.diff(self.points, axis=0)
        self.seg_len = np.hypot(seg[:, 0], seg[:, 1]) if len(seg) else np.zeros(0)
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.length = float(self.cum[-1])

    def at(self, s: float) -> tuple[float, float]:
        if len(self.points) == 1 or s <= 0:
            return float(self.points[0, 0]), float(self.points[0, 1])
        if s >= self.length:
            return float(self.points[-1, 0]), float(self.points[-1, 1])
        i = int(np.searchsorted(self.cum, s, side="right")) - 1
        u = (s - self.cum[i]) / self.seg_len[i] if self.seg_len[i] > 0 else 0.0
        a, b = self.points[i], self.points[i + 1]
        return float(a[0] + u * (b[0] - a[0])), float(a[1] + u * (b[1] - a[1]))

    def project(self, x: float, y: float, s_from: float, window: float) -> float:
        """Arc length of the closest point, searched only in [s_from, s_from + window] (progress never jumps)."""
        if len(self.points) < 2:
            return 0.0
        i0 = max(0, int(np.searchsorted(self.cum, s_from, side="right")) - 1)
        i1 = min(len(self.seg_len), int(np.searchsorted(self.cum, s_from + window, side="right")) + 1)
        best_s, best_d = s_from, math.inf
        for i in range(i0, i1):
            L = self.seg_len[i]
            if L <= 0:
                continue
            ax, ay = self.points[i]
            bx, by = self.points[i + 1]
            u = max(0.0, min(1.0, ((x - ax) * (bx - ax) + (y - ay) * (by - ay)) / (L * L)))
            d = math.hypot(ax + u * (bx - ax) - x, ay + u * (by - ay) - y)
            if d < best_d:
                best_d, best_s = d, float(self.cum[i] + u * L)
        return max(s_from, best_s)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def follow(path: Path, x: float, y: float, yaw: float, progress: float, cruise: float,
           cfg: FollowerConfig = FollowerConfig(), reverse: bool = False, through: bool = False) -> FollowCommand:
    """One control step of pure pursuit along ``path`` at up to ``cruise`` m/s.

    ``reverse`` is the direction of the previous step (False for a fresh route); the answer says which way to
    drive now. Backward, the robot pursues with its tail: the same geometry with the heading turned by pi, and a
    negative speed. ``through``: the end of ``path`` is not a stop (the way goes on past it), so the robot does
    not ease into it."""
    lookahead = max(cfg.lookahead_min, cfg.lookahead_gain * cruise)
    progress = path.project(x, y, progress, window=2.0 * lookahead + 1.0)
    remaining = path.length - progress
    ex, ey = path.points[-1]
    dist_end = math.hypot(ex - x, ey - y)
    if dist_end <= cfg.arrive_radius and remaining <= cfg.arrive_radius + lookahead:
        return FollowCommand(0.0, 0.0, progress, remaining, True, reverse)
    tx, ty = path.at(progress + lookahead)
    bearing = math.atan2(ty - y, tx - x)
    ahead = abs(_wrap(bearing - yaw))
    if not cfg.can_reverse or reverse and ahead < cfg.forward_within:
        reverse = False
    elif not reverse and ahead > cfg.reverse_beyond:
        reverse = True
    alpha = _wrap(bearing - yaw - (math.pi if reverse else 0.0))
    Ld = max(1e-6, math.hypot(tx - x, ty - y))
    if abs(alpha) > cfg.turn_in_place:
        # slow down the turn as the error closes, so it does not overshoot back past the threshold
        turn = min(cfg.max_yaw_rate, 2.0 * abs(alpha))
        return FollowCommand(0.0, math.copysign(turn, alpha), progress, remaining, False, reverse)
    # the arc's speed: as fast as the robot can turn the arc pure pursuit asks for (its yaw rate is 2 v sin(a)/Ld),
    # never slower: a cos(a) slow-down on every gentle arc cost a walking robot a quarter second at each doorway
    sin_a = abs(math.sin(alpha))
    speed = cruise if sin_a < 1e-9 else min(cruise, cfg.max_yaw_rate * Ld / (2.0 * sin_a))
    if not through:
        speed = min(speed, max(0.3, 0.8 * dist_end))  # ease into the end of the route
    yaw_rate = 2.0 * speed * math.sin(alpha) / Ld  # the same sign backward: the tail leads
    yaw_rate = max(-cfg.max_yaw_rate, min(cfg.max_yaw_rate, yaw_rate))
    return FollowCommand(-speed if reverse else speed, yaw_rate, progress, remaining, False, reverse)
