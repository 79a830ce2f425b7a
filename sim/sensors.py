"""Simulated sensors: position fixes, odometry, a drifting rate gyro and a forward accelerometer. Seeded, so runs are
deterministic.

The generator passed in is the sensors' own stream (``link.radio.subsystem_rng(seed, "sensors")`` in a run): draws
here never shift the robot's or the radio's, and theirs never shift these.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pymunk._chipmunk_cffi import lib

from sim.robots import Robot, normal_draws
from sim.world import World
from vehicle.io import Fix, Readings, Scan

_GET_ANGULAR_VELOCITY = lib.cpBodyGetAngularVelocity  # pymunk's property, without its Python layers
# the named tuples' documented ``_make``: built from every field in order, without the generated ``__new__``'s
# Python call and keyword handling (a reading every tick, a fix five times a second)
_READINGS, _FIX = Readings._make, Fix._make


@dataclass(frozen=True)
class SensorSpec:
    fix_hz: float = 5.0
    fix_std: float = 0.5  # m
    fix_dropout: float = 0.02  # chance a fix is missing even in the open
    gyro_noise: float = 0.01  # rad/s
    gyro_bias0: float = 0.005  # rad/s initial bias std
    gyro_bias_walk: float = 0.0005  # rad/s per sqrt(s)
    heading_hz: float = 10.0  # absolute heading reference (visual/lidar odometry), works underground too
    heading_std: float = 0.03  # rad
    accel_noise: float = 0.05  # m/s^2 per sample: forward accelerometer of the IMU
    accel_bias0: float = 0.02  # m/s^2 initial bias std
    scan_hz: float = 2.0  # a planar range sensor's sweeps (0: the robot has none)
    scan_beams: int = 90  # evenly around the robot: 4 degrees apart, a quarter metre apart at 3.6 m
    scan_range: float = 8.0  # m
    scan_std: float = 0.02  # m per beam


class Sensors:
    def __init__(self, robot: Robot, world: World, rng: np.random.Generator, spec: SensorSpec = SensorSpec()) -> None:
        self.robot, self.world, self.rng, self.spec = robot, world, rng, spec
        self.bias = rng.normal(0.0, spec.gyro_bias0)
        # the IMU draws from its own stream (a jump ahead of the shared one, which it leaves where it was), so
        # adding it did not change what the other sensors draw for a given seed
        self.imu_rng = np.random.Generator(rng.bit_generator.jumped())
        self.accel_bias = self.imu_rng.normal(0.0, spec.accel_bias0)
        self.imu_normal = normal_draws(self.imu_rng).__next__  # the accelerometer noise: all the IMU draws after
        # the range sensor: a stream of its own (two jumps ahead), for the same reason
        self.scan_rng = np.random.Generator(rng.bit_generator.jumped(2))
        self.scan_bearings = np.arange(spec.scan_beams) * (2.0 * math.pi / max(1, spec.scan_beams))
        self._next_scan = 0.0
        self._next_fix = 0.0
        self._next_heading = 0.0
        self.fixes = 0
        self.denied_ticks = 0
        self._walk_dt, self._walk = math.nan, 0.0  # the bias walk's step for the last dt: sigma * sqrt(dt)
        # what ``read`` uses every tick, looked up once: the stream's scalar draw and the body's chipmunk handle
        self._normal = rng.standard_normal
        self._body = robot.body._body

    def read(self, t: float, dt: float) -> Readings:
        """This tick's readings. Written for the tick's budget: ``sigma * rng.standard_normal()`` is the draw
        ``rng.normal(0.0, sigma)`` makes, bit for bit (numpy computes loc + scale * z), at half the cost of the
        argument handling; the gyro reads the body's rate from chipmunk directly (the same double)."""
        s, normal, robot = self.spec, self._normal, self.robot
        if dt != self._walk_dt:
            self._walk_dt, self._walk = dt, s.gyro_bias_walk * math.sqrt(dt)
        self.bias += self._walk * normal()
        # all Python floats already: the body's rate, the bias and the draws
        gyro = _GET_ANGULAR_VELOCITY(self._body) + self.bias + s.gyro_noise * normal()
        fix = None
        if t + 1e-9 >= self._next_fix:
            self._next_fix = t + 1.0 / s.fix_hz
            x, y, _ = robot.pose
            if self.world.gps_denied(x, y):
                self.denied_ticks += 1
            elif self.rng.random() >= s.fix_dropout:
                fix = _FIX((x + s.fix_std * normal(), y + s.fix_std * normal(), s.fix_std))
                self.fixes += 1
        heading = None
        if t + 1e-9 >= self._next_heading:
            self._next_heading = t + 1.0 / s.heading_hz
            heading = robot.pose[2] + s.heading_std * normal()
        accel = robot.accel + self.accel_bias + s.accel_noise * self.imu_normal()
        scan = None
        if s.scan_hz > 0.0 and t + 1e-9 >= self._next_scan:
            self._next_scan = t + 1.0 / s.scan_hz
            scan = self._scan()
        return _READINGS((t, robot.odometry_speed(dt), gyro, fix, heading, s.heading_std, accel, scan))

    def _scan(self) -> Scan:
        """A sweep of the range sensor from the robot's true pose: each beam's distance to the first wall, with
        noise, or inf where no wall is within reach."""
        s = self.spec
        x, y, yaw = self.robot.pose
        r = self.world.ranges(x, y, yaw + self.scan_bearings, s.scan_range)
        r = r + s.scan_std * self.scan_rng.standard_normal(len(r))
        return Scan(self.scan_bearings, np.maximum(r, 0.0), s.scan_range)
