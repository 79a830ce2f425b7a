"""The companion's rover's lidar: the native rover's range sensor, as a lidar driver on the vehicle reports it to the
companion, OBSTACLE_DISTANCE from another component of the autopilot's system (docs/architecture.md §11.4).

Why: the native rover sweeps a 360-degree lidar (``sim.sensors.SensorSpec``: 90 beams, 8 m, 2 cm noise, 2 Hz) and
its return keeps its body off what it sees. The autopilots' own range inputs are few: ArduPilot's JSON backend takes
six rangefinders (``sim.firmware.rangefinders``), and six beams leave gaps a door jamb fits in (measured over
gen:office seeds 1-10 beside ArduPilot with the rangefinders alone: returns touched a wall in 4 of 10, three of them
jammed against a wall the operator had left the rover beside, which no beam pointed at). So the rover carries the
native rover's lidar too, as companion computers on rovers often do: its driver (MAV_COMP_ID_OBSTACLE_AVOIDANCE of the
vehicle's system) sends each sweep as OBSTACLE_DISTANCE in the body frame, 72 sectors of 5 degrees (the message's
most), each sector the range along its centre, in cm, max_distance + 1 where no wall is within reach. It reaches
the companion on the vehicle's side of the radio, as the autopilot's own messages do; nothing of it goes through
the autopilot.
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as apm

from sim.robots import Robot
from sim.sensors import SensorSpec
from sim.world import World

SECTORS = 72  # OBSTACLE_DISTANCE's distances
INCREMENT = 360.0 / SECTORS  # degrees a sector
COMPID = apm.MAV_COMP_ID_OBSTACLE_AVOIDANCE
NATIVE = SensorSpec()  # the native rover's range sensor
MIN_CM = 5


class Lidar:
    """The rover's lidar and its driver: ``due(t)``, then ``frame(t, sysid)`` the OBSTACLE_DISTANCE of a sweep from
    the robot's true pose, packed as the driver (``sysid``, COMPID) sends it. Draws its noise from its own stream."""

    def __init__(self, world: World, robot: Robot, rng: np.random.Generator, spec: SensorSpec = NATIVE) -> None:
        self.world, self.robot, self.rng = world, robot, rng
        self.period = 1.0 / spec.scan_hz
        self.reach, self.noise = spec.scan_range, spec.scan_std
        self.bearings = np.radians(np.arange(SECTORS) * INCREMENT)
        self.next_at = 0.0
        self.sweeps = 0
        self.enc: apm.MAVLink | None = None

    def due(self, t: float) -> bool:
        return t + 1e-9 >= self.next_at

    def distances(self) -> list[int]:
        """One sweep from the robot's true pose: cm per sector, max + 1 where nothing is within reach."""
        x, y, yaw = self.robot.pose
        r = self.world.ranges(x, y, yaw + self.bearings, self.reach)
        r = np.maximum(r + self.noise * self.rng.standard_normal(SECTORS), 0.0)
        high = round(self.reach * 100)
        return [high + 1 if not math.isfinite(v) or v > self.reach else max(MIN_CM, round(v * 100)) for v in r]

    def frame(self, t: float, sysid: int) -> bytes:
        self.next_at = t + self.period
        if self.enc is None or self.enc.srcSystem != sysid:
            self.enc = apm.MAVLink(None, sysid, COMPID)
        self.sweeps += 1
        msg = apm.MAVLink_obstacle_distance_message(round(t * 1e6), apm.MAV_DISTANCE_SENSOR_LASER, self.distances(),
                                                    0, MIN_CM, round(self.reach * 100), INCREMENT, 0.0,
                                                    apm.MAV_FRAME_BODY_FRD)
        data = bytes(msg.pack(self.enc))
        self.enc.seq = (self.enc.seq + 1) % 256
        return data
