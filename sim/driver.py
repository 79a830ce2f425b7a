"""The simulator's side of ``vehicle.io.RobotDriver``: a pymunk robot and its sensors.

The vehicle loop commands and reads it exactly as it would a real robot's driver; the simulation loop steps the
physics between ticks with ``advance``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from link.radio import subsystem_rng
from link.storage import remove_leftovers
from sim.robots import Robot, make_robot
from sim.scenario import Scenario
from sim.sensors import Sensors
from sim.world import World
from vehicle.contingency import Contingency
from vehicle.core import Core, boot_core
from vehicle.endpoint import Endpoint
from vehicle.io import Readings
from vehicle.params import Params, load_defaults, read_parm_file


class SimDriver:
    """``rng`` drives the robot's physics noise (wheel scale, slip); ``sensor_rng``, when given, the sensors' own
    noise, so what the robot does cannot shift what its sensors read (the runner passes both, by subsystem)."""

    def __init__(self, scenario: Scenario, vehicle: str, rng: np.random.Generator,
                 sensor_rng: np.random.Generator | None = None) -> None:
        self.world: World = scenario.world()
        x, y, yaw = scenario.start
        self.robot: Robot = make_robot(vehicle, self.world, x, y, yaw, rng)
        self.sensors = Sensors(self.robot, self.world, rng if sensor_rng is None else sensor_rng)
        self.mav_type = self.robot.mav_type
        # the vehicle calls these every tick: the robot's and the sensors' own methods, with no forwarding call
        self.command: Callable[[float, float], None] = self.robot.command
        self.read: Callable[[float, float], Readings] = self.sensors.read
        # the three calls of every physics step, bound once rather than looked up through two objects each tick
        self._before_step = self.robot.before_step
        self._world_step = self.world.step
        self._after_step = self.robot.after_step

    def advance(self, dt: float) -> None:
        """One physics step of ``dt`` seconds: the robot pushes, pymunk steps, the robot reads where it went."""
        self._before_step(dt)
        self._world_step(dt)
        self._after_step(dt)

    @property
    def pose(self) -> tuple[float, float, float]:
        return self.robot.pose


def simulated_vehicle(scenario: Scenario, kind: str, seed: int, param_file: Path | None = None,
                      boot_epoch: int | None = None, contingency: Contingency | None = None,
                      on_epoch: Callable[[int], str | None] | None = None,
                      **endpoint_options) -> tuple[SimDriver, Core, Endpoint]:
    """The scenario's robot with the real onboard software on it: boot parameters from ``param_file`` (or the
    defaults; StoredFileError if it is damaged), then the scenario's own, as `sim run` and `sim serve` both start
    it. ``boot_epoch`` None (`sim run`) derives the first epoch from ``seed``; `sim serve` draws one. The robot
    and its sensors draw from their own streams of ``seed`` (``link.radio.subsystem_rng``). ``contingency`` is a
    baseline link-loss behaviour to fly instead of the return plan (``sim.policies``); ``on_epoch`` is told of each
    epoch the vehicle issues (`sim serve` keeps them: ``vehicle.epochs.EpochLog.issued``)."""
    driver = SimDriver(scenario, kind, subsystem_rng(seed, "robot"), subsystem_rng(seed, "sensors"))
    if param_file is not None:
        remove_leftovers(param_file)
    stored = read_parm_file(param_file) if param_file is not None and param_file.is_file() else None
    params = Params(stored) if stored is not None else load_defaults()
    if stored is None or "RTL_BODY_R" not in stored:
        # the simulated robot's footprint, set as its integrator would set a real one's (a stored value stays)
        params.set("RTL_BODY_R", driver.robot.shape.radius)
    for k, v in scenario.params.items():
        params.set(k, v)
    vehicle = boot_core(driver, params, scenario.start, 0.0, seed=seed, boot_epoch=boot_epoch, contingency=contingency,
                        on_epoch=on_epoch)
    return driver, vehicle, Endpoint(vehicle, param_file=param_file, **endpoint_options)
