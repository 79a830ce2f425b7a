"""``smartrtl``: ArduPilot SmartRTL's documented rules, on this vehicle.

The path (``SmartRTLPath``), as the ArduPilot wiki and parameter docs describe it: the position is sampled at
3 Hz and a point is added when the vehicle has moved more than SRTL_ACCURACY (2 m) from the last point; the path
is simplified with Ramer-Douglas-Peucker at half the accuracy (1 m) and loops are cut where two segments come
closer than 0.99 x accuracy (1.98 m), using a pairwise segment scan; the buffer holds SRTL_POINTS (300) points,
home first, and when it stays full for 15 s (cleanup cannot make room) SmartRTL deactivates for the rest of the
flight.

The failsafe (``SmartRTL``): Rover's GCS failsafe triggers FS_GCS_TIMEOUT after the last GCS heartbeat and acts
after FS_TIMEOUT (1.5 s) more; a real Rover SITL switched to SMART_RTL 4.55 s after its last heartbeat with
FS_GCS_TIMEOUT 3. FS_GCS_TIMEOUT is this vehicle's LNK_TIMEOUT, so the robot stands still from COMMS_LOST until
then (a heartbeat in that time clears the failsafe and the block ends); an operator's RTL switches to it at
once. It then runs a thorough cleanup and
retraces the path newest point first to home, at the return speed returnlink would use, and does not stop when
the link comes back (it stays in SMART_RTL until home). With SmartRTL deactivated, FS_ACTION 3 ("SmartRTL or
RTL") falls back to RTL: a straight line home. Points are not recorded while the return runs; after a return the
path starts again from where it ended.
"""

from __future__ import annotations

import math

import numpy as np

from sim.policies.base import Baseline, Command, PathDriver, return_speed
from vehicle.lease import ExpireReason, Holder
from vehicle.port import Snapshot
from vehicle.trail import douglas_peucker, seg_dist

SRTL_ACCURACY = 2.0  # m
SRTL_POINTS = 300
SRTL_SAMPLE_HZ = 3.0
SRTL_FULL_TIMEOUT = 15.0  # s full before deactivating
FS_TIMEOUT = 1.5  # s a failsafe condition must last before its action


def _seg_seg_dist(p1: tuple[float, float], p2: tuple[float, float], q1: tuple[float, float],
                  q2: tuple[float, float]) -> float:
    """Closest distance of two segments that do not cross (SmartRTL's loop test), with the trail's point-segment
    distance."""
    return min(seg_dist(*p1, *q1, *q2), seg_dist(*p2, *q1, *q2), seg_dist(*q1, *p1, *p2), seg_dist(*q2, *p1, *p2))


def _rdp(pts: list[tuple[float, float]], tol: float) -> list[tuple[float, float]]:
    """Ramer-Douglas-Peucker with the trail's implementation (no anchors but the two ends)."""
    if len(pts) < 3:
        return pts
    keep = douglas_peucker(np.array(pts), tol, np.zeros(len(pts), dtype=bool))
    return [p for p, k in zip(pts, keep, strict=True) if k]


class SmartRTLPath:
    """SmartRTL's bounded path memory (see the module docstring for its rules)."""

    def __init__(self, accuracy: float = SRTL_ACCURACY, max_points: int = SRTL_POINTS,
                 timeout: float = SRTL_FULL_TIMEOUT) -> None:
        self.accuracy, self.max_points, self.timeout = accuracy, max_points, timeout
        self.points: list[tuple[float, float]] = []
        self.active = True
        self.deactivated_at: float | None = None
        self._next_sample = 0.0
        self._full_since: float | None = None
        self.pair_checks = 0

    def update(self, x: float, y: float, t: float) -> None:
        if not self.active or t < self._next_sample:
            return
        self._next_sample = t + 1.0 / SRTL_SAMPLE_HZ
        p = (float(x), float(y))
        if self.points and math.dist(p, self.points[-1]) <= self.accuracy:
            return
        if len(self.points) >= self.max_points:
            self._cleanup()
        if len(self.points) >= self.max_points:
            if self._full_since is None:
                self._full_since = t
            if t - self._full_since >= self.timeout:
                self.active = False
                self.deactivated_at = t
            return
        self._full_since = None
        self.points.append(p)

    def restart(self, x: float, y: float) -> None:
        """The path begins again at ``(x, y)`` (home at arming, or where a return left the vehicle)."""
        self.points = [(float(x), float(y))]
        self._full_since = None

    def thorough_cleanup(self) -> None:
        """Simplify and prune the whole path at once, as SmartRTL does when the return starts."""
        self._cleanup()

    def _cleanup(self) -> None:
        self.points = _rdp(self.points, 0.5 * self.accuracy)
        # loop pruning: O(n^2) pair scan of non-adjacent segments
        pts = self.points
        i = 0
        while i < len(pts) - 3:
            cut = None
            for j in range(len(pts) - 2, i + 1, -1):
                self.pair_checks += 1
                if _seg_seg_dist(pts[i], pts[i + 1], pts[j], pts[j + 1]) < 0.99 * self.accuracy:
                    cut = j
                    break
            if cut is not None:
                pts = pts[: i + 1] + pts[cut + 1 :]
            i += 1
        self.points = pts


class SmartRTL(Baseline):
    """The GCS failsafe with FS_ACTION 3 (SmartRTL or RTL) on this vehicle's lease book."""

    halts_on_regain = False

    def __init__(self, accuracy: float = SRTL_ACCURACY, max_points: int = SRTL_POINTS,
                 fs_timeout: float = FS_TIMEOUT) -> None:
        super().__init__()
        self.path = SmartRTLPath(accuracy, max_points)
        self.fs_timeout = fs_timeout
        self.homed = False
        self.returning = False
        self.driver: PathDriver | None = None
        self.fallback = False  # deactivated: it flew RTL instead
        self.lost_at = 0.0  # when the failsafe condition began (the block started after COMMS_LOST)

    def observe(self, vehicle: Snapshot, t: float) -> None:
        s = vehicle.status()
        p = s.pose
        cur = s.book.current
        if self.returning and (cur is None or cur.holder is Holder.OPERATOR):
            self.finished(vehicle, t)  # taken back by the operator before it ended
        if not s.armed or self.returning:
            return
        if not self.homed:
            self.path.restart(p.x, p.y)
            self.homed = True
        self.path.update(p.x, p.y, t)

    @property
    def holding(self) -> bool:
        """Standing still between COMMS_LOST and the failsafe acting FS_TIMEOUT later."""
        return self.returning and self.driver is None

    def begin(self, vehicle: Snapshot, t: float, x: float, y: float) -> None:
        """After a link loss SMART_RTL takes over only when the failsafe acts (``_act``); an operator's RTL (the
        mode switched by hand) takes over at once."""
        self.driver = None
        self.returning = True
        # the failsafe condition starts with the vehicle's COMMS_LOST: silence for FS_GCS_TIMEOUT (= LNK_TIMEOUT),
        # or, on this vehicle, a delivery below LNK_MIN_Q for as long; waiting instead for silence since the last
        # packet heard would never act on a marginal link whose lucky packets keep arriving, while the lease book
        # has already taken the operator's control away
        self.lost_at = t
        if not vehicle.status().book.link.lost:
            self._act(vehicle, t, x, y)

    def tick(self, vehicle: Snapshot, t: float, x: float, y: float, yaw: float) -> Command:
        if self.driver is None:
            link = vehicle.status().book.link
            if not link.lost:
                return 0.0, 0.0, ExpireReason.COMPLETED  # the heartbeat came back first: the failsafe cleared
            if t + 1e-9 < self.lost_at + self.fs_timeout:
                return 0.0, 0.0, None
            self._act(vehicle, t, x, y)
        assert self.driver is not None
        return self.driver.step(vehicle, t, x, y, yaw)

    def _act(self, vehicle: Snapshot, t: float, x: float, y: float) -> None:
        self.acted.append(t)
        if self.path.active and self.path.points:
            self.path.thorough_cleanup()
            pts = [(x, y)] + self.path.points[::-1]
        else:
            self.fallback = True
            home = vehicle.status().home
            pts = [(x, y), (float(home[0]), float(home[1]))]
        self.route = np.array(pts)
        self.target = (float(self.route[-1, 0]), float(self.route[-1, 1]))
        self.driver = PathDriver(self.route, return_speed(vehicle), t)

    def finished(self, vehicle: Snapshot, t: float) -> None:
        self.returning = False
        p = vehicle.status().pose
        if self.path.active and self.homed:
            self.path.restart(p.x, p.y)
