"""The boundary between the vehicle software and a robot: what a driver reads and what it is told to do.

A real robot's driver implements ``RobotDriver`` over its wheels or legs and its sensors; the simulator implements
it over pymunk. The vehicle loop sees nothing else of the robot.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol


class Fix(NamedTuple):
    """A position fix in the local frame (x north, y east), with its 1-sigma error."""

    x: float
    y: float
    std: float


class Readings(NamedTuple):
    """One control tick's sensor data. A named tuple rather than a frozen dataclass: a driver builds one every
    20 ms tick, and a tuple is built at a third of the cost (a frozen dataclass sets each of its seven fields
    through ``object.__setattr__``), with the same names and immutability."""

    t: float
    speed: float  # odometry forward speed, m/s
    yaw_rate: float  # rate gyro, rad/s (clockwise positive, NED)
    fix: Fix | None
    heading: float | None = None  # absolute heading (compass, lidar or visual odometry), rad
    heading_std: float = 0.05
    accel: float | None = None  # forward acceleration from the IMU, m/s^2 (None: the robot has no accelerometer)


class RobotDriver(Protocol):
    """``mav_type`` is the HEARTBEAT type the vehicle reports (a composition may override it, as the companion's
    does: ``vehicle.endpoint.Endpoint``)."""

    mav_type: int

    def command(self, speed: float, yaw_rate: float) -> None: ...

    def read(self, t: float, dt: float) -> Readings: ...
