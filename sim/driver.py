"""The simulator's side of ``vehicle.io.RobotDriver``: a pymunk robot and its sensors.

The vehicle loop commands and reads it exactly as it would a real robot's driver; the simulation loop steps the
physics between ticks with ``advance``.
"""

from __future__ import annotations

import numpy as np

from sim.robots import Robot, make_robot
from sim.scenario import Scenario
from sim.sensors import Sensors
from sim.world import World
from vehicle.io import Readings


class SimDriver:
    def __init__(self, scenario: Scenario, vehicle: str, rng: np.random.Generator) -> None:
        self.world: World = scenario.world()
        x, y, yaw = scenario.start
        self.robot: Robot = make_robot(vehicle, self.world, x, y, yaw, rng)
        self.sensors = Sensors(self.robot, self.world, rng)
        self.mav_type = self.robot.mav_type

    def command(self, speed: float, yaw_rate: float) -> None:
        self.robot.command(speed, yaw_rate)

    def read(self, t: float, dt: float) -> Readings:
        return self.sensors.read(t, dt)

    def advance(self, dt: float) -> None:
        """One physics step of ``dt`` seconds."""
        self.robot.before_step(dt)
        self.world.step(dt)
        self.robot.after_step(dt)

    @property
    def pose(self) -> tuple[float, float, float]:
        return self.robot.pose
