"""The vehicle's speed and yaw rate as the autopilot driven takes them: one steering a rules object names
(``vehicle.companion.rules``), so the driver sends a target without asking which autopilot it drives.

ArduPilot Rover (``RoverSteering``) takes a velocity and a turn rate in the body frame, executed for 3 s each; its
speed is governed (``vehicle.companion.governor``: the speed loop's foreseen overshoot taken off), and a turn in
place creeps on a rover that steers like a car, or it never turns at all. Position targets never time out, so none
is ever sent. PX4 (``OffboardSteering``) takes a speed and a bearing, has no reverse in Offboard, and a zero vector
means north (``vehicle.companion.px4``): a backward command becomes an about-turn.
"""

from __future__ import annotations

import math
from typing import Protocol

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion import px4
from vehicle.companion.governor import Governor

TARGET_PERIOD = 0.1  # s between velocity targets (the autopilot drops a stream silent for 3 s)
CREEP = 0.3  # m/s: a rover that steers like a car turns "in place" by creeping, or it never turns at all
VELOCITY_AND_YAW_RATE = 0b0000_0101_1100_0111  # type mask: ignore x y z, ax ay az, yaw; use vx vy vz and yaw rate


class Estimate(Protocol):
    """What a steering reads of the autopilot (``vehicle.companion.observed.Observed``)."""

    sysid: int | None
    compid: int
    params: dict[str, float]

    def yaw(self) -> float | None: ...

    def speed_along(self, t: float) -> tuple[float, float] | None: ...


class RoverSteering:
    """ArduPilot Rover's targets: body-frame velocity and turn rate, the speed governed."""

    def __init__(self, pivots: bool = False) -> None:
        """``pivots``: the rover turns on the spot (skid steering); otherwise a turn in place creeps."""
        self.pivots = pivots
        self.governor = Governor()

    def begin(self) -> None:
        """A return takes the autopilot (the governor keeps what it learnt of the speed loop)."""

    def target(self, enc: apm.MAVLink, seen: Estimate, t: float, speed: float, yaw_rate: float, direction: float):
        """One velocity + turn-rate target in the body frame (position, acceleration and yaw ignored); the speed
        governed against the fresh estimate; a turn in place creeps ``direction``-wards unless the rover pivots."""
        along = seen.speed_along(t)
        speed = speed if along is None else self.governor.target(speed, *along)
        if not self.pivots and abs(speed) < 0.05 and abs(yaw_rate) > 0.05:
            speed = CREEP * direction
        return enc.set_position_target_local_ned_encode(
            0, seen.sysid, seen.compid, apm.MAV_FRAME_BODY_NED, VELOCITY_AND_YAW_RATE, 0, 0, 0, speed, 0, 0, 0, 0, 0,
            0, yaw_rate)

    def zero(self, enc: apm.MAVLink, seen: Estimate, t: float):
        """A zero velocity and turn-rate target (GUIDED): the rover brakes to a stand at its deceleration limit."""
        return enc.set_position_target_local_ned_encode(
            0, seen.sysid, seen.compid, apm.MAV_FRAME_BODY_NED, VELOCITY_AND_YAW_RATE, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)


class OffboardSteering:
    """PX4's targets: a speed and a bearing ahead of the turn asked for; a backward command an about-turn."""

    def __init__(self, pivots: bool = False) -> None:
        """(``pivots`` is ArduPilot's: PX4's differential rover turns on the spot by itself.)"""
        self.yaw_p = px4.YAW_P  # PX4's RO_YAW_P, once read: how its yaw loop answers a bearing
        self.about: float | None = None  # the NED bearing of an about-turn in place of a backward drive
        self.about_at = 0  # ... begun at this target
        self.targets = 0  # targets sent

    def begin(self) -> None:
        """A return takes the autopilot: no about-turn left over from the last."""
        self.about = None

    def target(self, enc: apm.MAVLink, seen: Estimate, t: float, speed: float, yaw_rate: float, direction: float):
        """PX4's target for the vehicle's command: a speed and a bearing ahead of the turn asked for; a backward
        command an about-turn to the heading behind, kept until it is done or the command is forward (or nothing)
        again (``vehicle.companion.px4``). While it lasts the navigator's own turns are not passed on: they steer a
        tail that PX4 is turning away (measured: a rover that stood stuck for 15 s, the navigator turning it back
        toward a route it was pivoting to)."""
        yaw_p = seen.params.get("RO_YAW_P", 0.0)
        if yaw_p > 0:
            self.yaw_p = yaw_p
        yaw = seen.yaw()
        if self.about is not None:
            # done once turned (then the route lies ahead, and the navigator drives it forward), or once the
            # navigator asks for forward speed or for nothing; never longer than a slow full turn
            turned = yaw is not None and abs(math.remainder(yaw - self.about, math.tau)) < px4.ABOUT_DONE
            idle = abs(speed) <= 0.05 and abs(yaw_rate) <= 0.05
            if turned or idle or speed > 0.05 or self.targets - self.about_at > px4.ABOUT_TARGETS:
                self.about = None
        elif speed < -0.05 and yaw is not None:
            self.about, self.about_at = yaw + math.pi, self.targets
        self.targets += 1
        if self.about is not None:
            return px4.bearing_target(enc, seen.sysid, seen.compid, self.about)
        return px4.velocity_target(enc, seen.sysid, seen.compid, speed, yaw_rate, TARGET_PERIOD, self.yaw_p)

    def zero(self, enc: apm.MAVLink, seen: Estimate, t: float):
        """A stop in Offboard: a tiny vector along the rover's own heading (a zero one would mean north)."""
        return self.target(enc, seen, t, 0.0, 0.0, 1.0)


Steering = RoverSteering | OffboardSteering
