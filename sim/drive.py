"""A closed loop without the radio or MAVLink: robot, sensors, estimator, trail and path follower.

It is what the robot-model tests and the trail benchmark drive, and the physics-plus-estimator floor the SITL
benchmark compares against. The full vehicle loop (vehicle/app) adds leases and MAVLink on top of the same parts.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from sim.robots import Robot, make_robot
from sim.scenario import Scenario
from sim.sensors import Sensors
from sim.world import World
from vehicle.estimator import Estimator
from vehicle.navigation import FollowerConfig, Path, follow
from vehicle.trail import Crumb, Trail, TrailConfig

DT = 0.02  # 50 Hz control tick


@dataclass
class Log:
    t: list[float] = field(default_factory=list)
    true: list[tuple[float, float]] = field(default_factory=list)
    est: list[tuple[float, float]] = field(default_factory=list)
    std: list[float] = field(default_factory=list)
    fix_err: list[float] = field(default_factory=list)

    def rmse(self) -> float:
        a, b = np.array(self.true), np.array(self.est)
        return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1)))) if len(a) else 0.0


class Rig:
    """One robot in one world, stepped in lockstep."""

    def __init__(self, scenario: Scenario, vehicle: str | None = None, seed: int | None = None,
                 trail_config: TrailConfig | None = None) -> None:
        self.scenario = scenario
        rng = np.random.default_rng(scenario.seed if seed is None else seed)
        self.world: World = scenario.world()
        x, y, yaw = scenario.start
        self.robot: Robot = make_robot(vehicle or scenario.vehicle, self.world, x, y, yaw, rng)
        self.sensors = Sensors(self.robot, self.world, rng)
        self.t = 0.0
        self.estimator = Estimator(x, y, yaw, 0.0, pos_std=0.3, yaw_std=0.02)
        self.trail = Trail(trail_config)
        self.log = Log()

    def step(self, speed: float, yaw_rate: float, link_good: Callable[[float, float], bool] | None = None) -> None:
        self.robot.command(speed, yaw_rate)
        self.robot.before_step(DT)
        self.world.step(DT)
        self.robot.after_step(DT)
        self.t += DT
        r = self.sensors.read(self.t, DT)
        self.estimator.predict(r.speed, r.yaw_rate, self.t, r.accel)
        if r.heading is not None:
            self.estimator.heading(r.heading, r.heading_std)
        tx, ty, _ = self.robot.pose
        if r.fix is not None:
            self.estimator.fix(r.fix.x, r.fix.y, r.fix.std)
            self.log.fix_err.append(math.hypot(r.fix.x - tx, r.fix.y - ty))
        p = self.estimator.pose
        good = link_good(p.x, p.y) if link_good else True
        self.trail.add(Crumb(p.x, p.y, self.t, p.std, good))
        self.log.t.append(self.t)
        self.log.true.append((tx, ty))
        self.log.est.append((p.x, p.y))
        self.log.std.append(p.std)

    def drive(self, points: np.ndarray, speed: float, timeout: float,
              link_good: Callable[[float, float], bool] | None = None, cfg: FollowerConfig | None = None) -> bool:
        """Follow a polyline on the estimated pose until arrival or timeout; True on arrival."""
        cfg = cfg or FollowerConfig()
        p0 = self.estimator.pose
        path = Path(np.vstack([[p0.x, p0.y], points]))
        progress, end, reverse = 0.0, self.t + timeout, False
        while self.t < end:
            p = self.estimator.pose
            cmd = follow(path, p.x, p.y, p.yaw, progress, speed, cfg, reverse)
            progress, reverse = cmd.progress, cmd.reverse
            if cmd.arrived:
                self.step(0.0, 0.0, link_good)
                return True
            self.step(cmd.speed, cmd.yaw_rate, link_good)
        return False

    def drive_route(self, link_good: Callable[[float, float], bool] | None = None) -> bool:
        """Drive the scenario operator's outbound route (waypoints with speeds)."""
        for x, y, v in self.scenario.route:
            if not self.drive(np.array([[x, y]]), v, timeout=300.0, link_good=link_good):
                return False
        return True
