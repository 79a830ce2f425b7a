"""The rover's rangefinders, as the ArduPilot firmware gets them in a run: six beams from the scenario's walls into
the JSON backend's ``rng_1`` ... ``rng_6`` (docs/architecture.md §11.4).

Why: a real rover carries range sensors and its autopilot reports them (one DISTANCE_SENSOR per rangefinder), and
the companion's return keeps its body off what they see (``vehicle.companion.ranges``). ArduPilot's JSON backend
reads ``rng_N`` (metres) from each physics reply into its simulated rangefinder N (RNGFNDn_TYPE 100, SITL); a value
that is not a number reads as "no data" and fails the pre-arm check, so a beam that meets no wall within reach
reports REACH + 1 m, which the firmware takes as out of range (DISTANCE_SENSOR's current_distance above its
max_distance: nothing within reach).

The six beams are a ring a rover's integrator mounts for driving both ways: forward and back, and 45 degrees off
each on either side (RNGFNDn_ORIENT 0, 1, 3, 4, 5, 7), from the body's centre, reaching REACH (the native rover's
lidar reach), with the native sensor's 2 cm noise a beam. No beam looks straight to the side: a jamb the body passes
was seen by a diagonal one the moment before, which the standoff remembers (``vehicle.standoff.remember``), and
the native return backs up routes behind it, where a ring of forward, side and back beams (tried first) left the
back corners blind: over gen:office seeds 2-9 every return contact with it came backing up with no return seen
within 2 m. They are measured RATE_HZ times a second of physics time, a rangefinder's pace,
not at every one of the firmware's 200 physics frames: the reply carries the last measurement between.

PX4 gets the same six as DISTANCE_SENSOR on its simulator link (``distance_sensors``), which its simulator_mavlink
module publishes as its own distance sensors and its MAVLink reports to the companion as DISTANCE_SENSOR, the way a
rangefinder driver's readings reach it on a real rover (``sim.px4.lockstep``).
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import common as mav

from sim.world import World

BEARINGS = tuple(math.radians(a) for a in (0.0, 45.0, 135.0, 180.0, -135.0, -45.0))  # rng_1..6, clockwise from ahead
ORIENT = (0, 1, 3, 4, 5, 7)  # their MAV_SENSOR_ORIENTATION: forward, forward-right, back-right, back, back-left,
# forward-left
REACH = 8.0  # m: the native rover's lidar reach (sim.sensors.SensorSpec.scan_range)
NOISE = 0.02  # m a beam (the native sensor's)
MIN_RANGE = 0.05  # m: the shortest the firmware believes; the body's own radius is far more
RATE_HZ = 20.0  # measurements a second of physics time (a rangefinder's pace; the companion asks for 10 Hz)
SITL_TYPE = 100  # RNGFNDn_TYPE: ArduPilot's simulated rangefinder, fed by the physics


def params() -> dict[str, float]:
    """The firmware parameters that give it these rangefinders: type, orientation and limits of each (ArduPilot
    4.6+ names the limits RNGFNDn_MIN / RNGFNDn_MAX, in metres)."""
    out: dict[str, float] = {}
    for n, orient in enumerate(ORIENT, start=1):
        out |= {f"RNGFND{n}_TYPE": SITL_TYPE, f"RNGFND{n}_ORIENT": orient, f"RNGFND{n}_MIN": MIN_RANGE,
                f"RNGFND{n}_MAX": REACH}
    return out


class Rangefinders:
    """The six beams of one rover, measured at RATE_HZ (``due`` / ``measure``); ``last`` the values the JSON
    replies carry. Draws its noise from its own stream."""

    def __init__(self, world: World, rng: np.random.Generator) -> None:
        self.world, self.rng = world, rng
        self.bearings = np.array(BEARINGS)
        self.last: tuple[float, ...] = (REACH + 1.0,) * len(BEARINGS)
        self.next_at = 0.0
        self.measured = 0

    def due(self, t: float) -> bool:
        return t + 1e-9 >= self.next_at

    def measure(self, t: float, x: float, y: float, yaw: float) -> tuple[float, ...]:
        """The six ranges from the pose (x north, y east, yaw) at ``t``; out of reach: REACH + 1."""
        self.next_at = t + 1.0 / RATE_HZ
        r = self.world.ranges(x, y, yaw + self.bearings, REACH)
        r = np.maximum(r + NOISE * self.rng.standard_normal(len(r)), 0.0)
        self.last = tuple(float(v) if v <= REACH else REACH + 1.0 for v in r)
        self.measured += 1
        return self.last


def distance_sensors(ranges: tuple[float, ...], time_boot_ms: int) -> list[mav.MAVLink_distance_sensor_message]:
    """The six ranges as DISTANCE_SENSOR messages (sensor id n-1 for rng_n; cm; out of reach: max + 1), for PX4's
    simulator link. Each carries its yaw as a quaternion too: PX4 keeps forward, back (PITCH_180), left and right as
    named orientations and reports any other, the diagonals here, as MAV_SENSOR_ROTATION_CUSTOM with the quaternion
    it was given (SimulatorMavlink::publish_distance_topic)."""
    low, high = round(MIN_RANGE * 100), round(REACH * 100)
    return [mav.MAVLink_distance_sensor_message(time_boot_ms & 0xFFFFFFFF, low, high,
                                                min(high + 1, round(r * 100)), mav.MAV_DISTANCE_SENSOR_LASER, n,
                                                mav.MAV_SENSOR_ROTATION_PITCH_180 if orient == 4 else orient, 0, 0.0,
                                                0.0, [math.cos(b / 2), 0.0, 0.0, math.sin(b / 2)])
            for n, (r, orient, b) in enumerate(zip(ranges, ORIENT, BEARINGS, strict=True))]
