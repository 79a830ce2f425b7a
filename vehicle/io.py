"""The boundary between the vehicle software and a robot: what a driver reads and what it is told to do.

A real robot's driver implements ``RobotDriver`` over its wheels or legs and its sensors; the simulator implements
it over pymunk. The vehicle loop sees nothing else of the robot.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple, Protocol

if TYPE_CHECKING:
    import numpy as np


class Fix(NamedTuple):
    """A position fix in the local frame (x north, y east), with its 1-sigma error."""

    x: float
    y: float
    std: float


class Scan(NamedTuple):
    """One sweep of a planar range sensor (lidar, a depth camera's floor slice): per beam its bearing from the
    robot's heading (rad, clockwise positive like the heading) and the range to the first return (m; ``max_range``
    or more, or inf: nothing within reach). What the return uses it for: ``vehicle.clearance``."""

    bearings: tuple[float, ...] | np.ndarray
    ranges: tuple[float, ...] | np.ndarray
    max_range: float


class Readings(NamedTuple):
    """One control tick's sensor data: an immutable record, built by the driver every tick."""

    t: float
    speed: float  # odometry forward speed, m/s
    yaw_rate: float  # rate gyro, rad/s (clockwise positive, NED)
    fix: Fix | None
    heading: float | None = None  # absolute heading (compass, lidar or visual odometry), rad
    heading_std: float = 0.05
    accel: float | None = None  # forward acceleration from the IMU, m/s^2 (None: the robot has no accelerometer)
    scan: Scan | None = None  # a range sensor's sweep, when one was taken this tick (None: none, or no sensor)


class RobotDriver(Protocol):
    """``mav_type`` is the HEARTBEAT type the vehicle reports (a composition may override it, as the companion's
    does: ``vehicle.endpoint.Endpoint``)."""

    mav_type: int

    def command(self, speed: float, yaw_rate: float) -> None: ...

    def read(self, t: float, dt: float) -> Readings: ...
