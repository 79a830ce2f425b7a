"""What the ground station itself saw of the robot's path: positions tagged with the link quality it heard them at.

The vehicle's breadcrumb trail stays on the vehicle; what reaches the station over standard MAVLink is its
estimated position (LOCAL_POSITION_NED, 4 Hz by default) whenever the link carries it. The station's own view is
what an operator needs on a map: where the robot was while the station could hear it, how well (the share of the
expected position reports that arrived), and where the reports stopped: the last position heard before a silence
is where the station lost the link. Pure: positions and times go in, nothing here reads a clock or a socket.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

POSITION_RATE = 4.0  # Hz: LOCAL_POSITION_NED's default rate on a returnlink vehicle
QUALITY_WINDOW = 2.0  # s of reports that make one quality figure
LOST_GAP = 2.0  # s without a position report: the station has lost the link
MIN_STEP = 0.25  # m between kept points (a parked robot adds nothing)
MAX_POINTS = 5000  # memory bound: the oldest half is thinned when full


@dataclass(frozen=True)
class TrackPoint:
    t: float
    north: float
    east: float
    quality: float  # 0..1: share of the expected position reports heard over QUALITY_WINDOW


@dataclass
class Track:
    """The station's history of the robot's position, with link quality and the points where the link was lost."""

    rate: float = POSITION_RATE
    points: list[TrackPoint] = field(default_factory=list)
    lost: list[TrackPoint] = field(default_factory=list)  # last point heard before each silence of LOST_GAP
    heard: list[float] = field(default_factory=list)  # report times within QUALITY_WINDOW
    last: TrackPoint | None = None  # the newest report, kept or not

    def quality(self, t: float) -> float:
        recent = [x for x in self.heard if x > t - QUALITY_WINDOW]
        return min(1.0, len(recent) / (QUALITY_WINDOW * self.rate))

    def add(self, t: float, north: float, east: float) -> None:
        """One position report received at station time ``t``."""
        if not (math.isfinite(north) and math.isfinite(east)):
            return
        if self.last is not None and t - self.last.t >= LOST_GAP:
            self.lost.append(self.last)
            self._keep(self.last)  # the loss point is always on the path drawn
        self.heard = [x for x in self.heard if x > t - QUALITY_WINDOW] + [t]
        p = TrackPoint(t, north, east, self.quality(t))
        self.last = p
        prev = self.points[-1] if self.points else None
        if prev is None or math.hypot(north - prev.north, east - prev.east) >= MIN_STEP:
            self._keep(p)

    def _keep(self, p: TrackPoint) -> None:
        if self.points and self.points[-1] == p:
            return
        self.points.append(p)
        if len(self.points) > MAX_POINTS:
            half = MAX_POINTS // 2
            self.points = self.points[:half:2] + self.points[half:]


def return_route(track: Track, position: tuple[float, float], start: tuple[float, float] | None,
                 target: tuple[float, float] | None, max_displacement: float) -> list[tuple[float, float]]:
    """The return route as the station can reconstruct it: its own track walked backward from the robot to the
    point nearest the vehicle's return target, cut where it leaves the displacement circle around the return
    start (the vehicle drives its own trail; this is the operator's picture of it)."""
    if target is None:
        return []
    pts = [(p.north, p.east) for p in track.points]
    if not pts:
        return [position, target]
    k = min(range(len(pts)), key=lambda i: math.dist(pts[i], target))
    back = list(reversed(pts[k:]))
    route = [position, *back, target]
    if start is None or not math.isfinite(max_displacement):
        return route
    out = [route[0]]
    for p in route[1:]:
        if math.dist(p, start) > max_displacement:
            break
        out.append(p)
    return out
