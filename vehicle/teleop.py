"""Teleoperation as the vehicle executes it: a setpoint bound to its lease, its dead-man, and the stick's scale.

A MANUAL_CONTROL or SET_POSITION_TARGET_LOCAL_NED that the lease rules let through becomes a ``Setpoint``: a speed
and a yaw rate that die with the lease they were sent under, or when not refreshed for ``SETPOINT_TTL``. The
vehicle loop checks the lease again at the actuator before it drives on one (``vehicle/control.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from vehicle.lease_terms import LeaseId
from vehicle.navigation import TURN_IN_PLACE

SETPOINT_TTL = 0.5  # s: a teleop setpoint not refreshed this long is dropped (dead-man)
MAX_TELEOP_SPEED = 2.0  # m/s at full stick
MAX_TELEOP_YAW_RATE = 1.2  # rad/s at full stick


@dataclass(frozen=True)
class Setpoint:
    """A teleop request, bound to the lease it was sent under: it dies with that lease."""

    speed: float
    yaw_rate: float
    lease: LeaseId
    until: float
    sender: int = 0


def velocity_to_command(vn: float, ve: float, yaw_rate: float | None, yaw: float) -> tuple[float, float]:
    """A NED velocity target for a unicycle: turn toward the velocity, drive the part of it along the heading.

    Far off the heading it turns in place first, as the return's navigator does: driving the cosine share of a
    velocity 60 degrees off swings a wide arc, and a robot left facing away from its way out (a return backs up)
    would sweep a U-turn into the corridor wall."""
    speed = math.hypot(vn, ve)
    if speed < 1e-3:
        return 0.0, yaw_rate or 0.0
    err = (math.atan2(ve, vn) - yaw + math.pi) % (2 * math.pi) - math.pi
    turn = max(-MAX_TELEOP_YAW_RATE, min(MAX_TELEOP_YAW_RATE, 2.0 * err)) if yaw_rate is None else yaw_rate
    if abs(err) > TURN_IN_PLACE:
        return 0.0, turn
    return speed * math.cos(err), turn
