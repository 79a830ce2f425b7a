"""What the baselines share: knowing when a new return chain starts, and driving a polyline to its end.

A baseline runs once per return chain (the leases one link loss made current): the first service lease of a
chain starts it, and once it has finished, the chain's later blocks end at once (COMPLETED), because the
baseline's own rules, not the scenario's plan, say what happens after a loss. Driving uses the vehicle's own
navigator and the same speed rule and STUCK rule as every return, so a baseline differs only in where it goes
and when it stops.
"""

from __future__ import annotations

import math

import numpy as np

from vehicle.lease import ExpireReason
from vehicle.navigation import FollowerConfig, Path, follow
from vehicle.port import Snapshot
from vehicle.service import STUCK_AFTER

Command = tuple[float, float, ExpireReason | None]


class PathDriver:
    """Pure pursuit along ``points`` (estimate frame) until the end, or STUCK when it stops getting closer."""

    def __init__(self, points: np.ndarray, speed: float, t: float) -> None:
        self.path = Path(points) if len(points) >= 2 else None
        self.speed = speed
        self.progress = 0.0
        self.reverse = False  # the follower's direction, passed back in as the service does (its hysteresis)
        self.best_remaining = math.inf
        self.last_progress_at = t

    def step(self, vehicle: Snapshot, t: float, x: float, y: float, yaw: float) -> Command:
        if self.path is None:
            return 0.0, 0.0, ExpireReason.COMPLETED
        cmd = follow(self.path, x, y, yaw, self.progress, self.speed,
                     FollowerConfig.from_params(vehicle.params), self.reverse)
        self.progress, self.reverse = cmd.progress, cmd.reverse
        if cmd.arrived:
            return 0.0, 0.0, ExpireReason.COMPLETED
        if cmd.remaining < self.best_remaining - 0.2:
            self.best_remaining, self.last_progress_at = cmd.remaining, t
        elif t - self.last_progress_at >= STUCK_AFTER:
            return 0.0, 0.0, ExpireReason.STUCK
        return cmd.speed, cmd.yaw_rate, None


def return_speed(vehicle: Snapshot) -> float:
    """RTL_SPEED, or the speed driven outbound: the same rule the returnlink service uses."""
    return vehicle.params["RTL_SPEED"] or vehicle.status().outbound_speed or 1.0


class Baseline:
    """A ``vehicle.contingency.Contingency`` run once per return chain, on the port's snapshot face
    (``vehicle.port.Snapshot``). Subclasses say how a return starts (``begin``) and how each tick goes (``tick``);
    ``route`` and ``target`` (estimate frame) are kept for the plots, and ``acted`` holds when each return took over
    the robot (for SmartRTL, FS_TIMEOUT after the lease did)."""

    halts_on_regain = True
    holding = False  # standing still by its rules right now (the vehicle then reports HOLDING)

    def __init__(self) -> None:
        self.chain: int | None = None
        self.done = False
        self.route: np.ndarray | None = None
        self.target: tuple[float, float] | None = None
        self.acted: list[float] = []

    def observe(self, vehicle: Snapshot, t: float) -> None:
        """Nothing to record by default."""

    def drive(self, vehicle: Snapshot, t: float, x: float, y: float, yaw: float) -> Command:
        cur = vehicle.status().book.current
        chain = cur.chain if cur is not None else None
        if chain != self.chain:
            self.chain, self.done = chain, False
            self.route, self.target = None, None
            self.begin(vehicle, t, x, y)
        if self.done:
            return 0.0, 0.0, ExpireReason.COMPLETED  # the chain's later blocks: this baseline has finished
        speed, yaw_rate, finished = self.tick(vehicle, t, x, y, yaw)
        if finished is not None:
            self.done = True
            self.finished(vehicle, t)
        return speed, yaw_rate, finished

    def begin(self, vehicle: Snapshot, t: float, x: float, y: float) -> None:
        """A new return chain starts (one link loss, or an operator's RTL): by default the baseline acts now."""
        self.acted.append(t)

    def tick(self, vehicle: Snapshot, t: float, x: float, y: float, yaw: float) -> Command:
        raise NotImplementedError

    def finished(self, vehicle: Snapshot, t: float) -> None:
        """The return ended (arrived, STUCK)."""
