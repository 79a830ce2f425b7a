"""Teleoperation on the wire (docs/architecture.md §4): MANUAL_CONTROL and velocity SET_POSITION_TARGET_LOCAL_NED.

Both streams arrive at 10 Hz from a station that drives; each frame becomes one teleop setpoint the lease rules
judge (``Vehicle.command``). A refused stream is announced once every REJECT_NOTICE_GAP seconds per sender, not
answered frame by frame. Speeds are clamped to the vehicle's limits; a non-finite number refuses the frame.
"""

from __future__ import annotations

import math

from link.setpoints import IGNORE_VELOCITY, IGNORE_YAW_RATE
from vehicle.lease import Verdict
from vehicle.port import VehiclePort
from vehicle.services.base import Counters, Outbox, Service, Source, Throttle, handles, mav
from vehicle.teleop import MAX_TELEOP_SPEED, MAX_TELEOP_YAW_RATE, velocity_to_command

BODY_FRAMES = frozenset((mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_FRD))
REJECT_NOTICE_GAP = 2.0  # s between STATUSTEXTs about one sender's refused teleop stream
STICK = 1000  # MANUAL_CONTROL axes run -1000..1000


class Teleop(Service):
    """Stick and velocity streams -> teleop setpoints, for the system ``sysid``."""

    def __init__(self, out: Outbox, vehicle: VehiclePort, counters: Counters, sysid: int) -> None:
        self.out = out
        self.vehicle = vehicle
        self.counters = counters
        self.sysid = sysid
        self.notices = Throttle(REJECT_NOTICE_GAP)

    @handles("MANUAL_CONTROL")
    def _on_manual_control(self, m, src: Source, t: float) -> None:
        if m.target not in (0, self.sysid):  # its one target field, a system id
            self.counters.wrong_target += 1
            return
        x, r = _clamp(m.x, -STICK, STICK), _clamp(m.r, -STICK, STICK)
        self.drive(x / STICK * MAX_TELEOP_SPEED, r / STICK * MAX_TELEOP_YAW_RATE, src, t)

    @handles("SET_POSITION_TARGET_LOCAL_NED")
    def _on_position_target(self, m, src: Source, t: float) -> None:
        mask = m.type_mask
        if mask & IGNORE_VELOCITY == IGNORE_VELOCITY:
            return  # no velocity in this target: only velocity teleop is supported on the ground
        vx, vy = _finite(m.vx), _finite(m.vy)
        yaw_rate = None if mask & IGNORE_YAW_RATE else _finite(m.yaw_rate)
        if m.coordinate_frame in BODY_FRAMES:
            speed, turn = vx, yaw_rate if yaw_rate is not None else 0.0
        else:
            speed, turn = velocity_to_command(vx, vy, yaw_rate, self.vehicle.status().pose.yaw)
        self.drive(speed, turn, src, t)

    def drive(self, speed: float, yaw_rate: float, src: Source, t: float) -> None:
        """One teleop setpoint (m/s forward, rad/s), clamped to the vehicle's limits and judged by the lease."""
        speed = _clamp(speed, -MAX_TELEOP_SPEED, MAX_TELEOP_SPEED)
        yaw_rate = _clamp(yaw_rate, -MAX_TELEOP_YAW_RATE, MAX_TELEOP_YAW_RATE)
        sender = src.sysid
        chk = self.vehicle.command(sender, src.compid, t, ("teleop", speed, yaw_rate))
        if not chk.executes and chk.verdict is not Verdict.QUEUE and self.notices.due(sender, t):
            self.out.statustext(f"teleop from {sender} refused: {chk.detail or chk.reason.name}",
                                mav.MAV_SEVERITY_WARNING)


def _finite(x: float) -> float:
    if not math.isfinite(x):
        raise ValueError("not a finite number")
    return float(x)


def _clamp(x: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, _finite(x)))
