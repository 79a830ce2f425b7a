"""What differs when the autopilot beside the companion is PX4 (docs/architecture.md §11.2): its modes, how a return
drives it in Offboard, its parameters' wire encoding. ``vehicle.companion.rules`` picks this or the ArduPilot
rules from the autopilot's HEARTBEAT (``autopilot`` 12 here, 3 there); ``vehicle.companion.autopilot`` drives both
through one driver.

What PX4's differential rover (``rover_differential``, airframe 1069 and the r1-rover tuning it shares) accepts in
Offboard, read from its source (``src/modules/mavlink/mavlink_receiver.cpp``,
``src/modules/rover_differential/DifferentialDriveModes/DifferentialOffboardMode``) and measured against the SITL:
- SET_POSITION_TARGET_LOCAL_NED in MAV_FRAME_LOCAL_NED (1) or MAV_FRAME_BODY_NED (8) only; any other frame is
  dropped with a "coordinate frame unsupported" STATUSTEXT. BODY_NED velocities are rotated into NED by PX4's own
  yaw as they arrive; BODY_NED positions are ignored.
- A position target (x, y used) drives there by pure pursuit at RO_SPEED_LIM and stops; a velocity target becomes a
  speed (the vector's norm) and a bearing (its direction) that the rover turns to (on the spot when more than
  RD_TRANS_DRV_TRN off) and drives along. So there is no reverse in Offboard, and a zero vector means bearing
  north: a stop must be a tiny vector along the rover's own heading, never (0, 0). The yaw and yaw-rate fields of
  this message are ignored by the rover (they only steer in attitude / body-rate Offboard, which comes from
  SET_ATTITUDE_TARGET), as are accelerations.
- Setpoints reach the controllers only while PX4 is in Offboard; before the switch they only prove that a stream
  runs (PX4 refuses Offboard without one fresher than COM_OF_LOSS_T), and PX4 leaves Offboard for COM_OBL_RC_ACT
  when the stream has been silent for COM_OF_LOSS_T.

So the companion drives PX4 with BODY_NED velocity targets at 10 Hz: speed = the vehicle's commanded speed, bearing
= the rover's heading plus the turn the commanded yaw rate asks for over one target period, scaled for PX4's yaw
loop (a proportional controller, RO_YAW_P, that turns toward the bearing: ``bearing_lead``). A backward command
becomes an about-turn (``bearing_target``: on the spot to the heading behind, held in the NED frame until the
navigator, seeing the route ahead again, asks for forward speed): the native navigator backs a rover up a route
that lies behind, steering with its tail, and answering that steering while PX4 pivots the nose would turn the rover
back and forth for ever (measured on a stand-in). Velocity rather than position,
because the native navigator speaks speed and yaw rate, and because a velocity stream is a dead-man with PX4's
COM_OF_LOSS_T: a companion that dies mid-return stops feeding it, and PX4 itself leaves Offboard for Hold.

The companion's other PX4 rules: Hold is nav state AUTO_LOITER (main mode AUTO, sub mode LOITER); DO_SET_MODE takes
PX4's main and sub mode as params 2 and 3; parameters travel bytewise (an INT32 parameter's bits sit in the float
``param_value``, PARAM_SET must name the parameter's own type or PX4 ignores it) where ArduPilot casts.
"""

from __future__ import annotations

import math
import struct

from pymavlink.dialects.v20 import ardupilotmega as apm

# PX4's HEARTBEAT.custom_mode: main mode in bits 16-23, sub mode in 24-31 (src/modules/commander/px4_custom_mode.h)
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STAB = 1, 2, 3, 4, 5, 6, 7
AUTO_LOITER, AUTO_MISSION, AUTO_RTL = 3, 4, 5


def custom_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT.custom_mode of PX4 main mode ``main``, sub mode ``sub``."""
    return (main << 16) | (sub << 24)


OFFBOARD = custom_mode(MAIN_OFFBOARD)
HOLD = custom_mode(MAIN_AUTO, AUTO_LOITER)
MODE_NAMES: dict[int, str] = {
    custom_mode(MAIN_MANUAL): "MANUAL", custom_mode(MAIN_ALTCTL): "ALTCTL", custom_mode(MAIN_POSCTL): "POSCTL",
    custom_mode(MAIN_AUTO, 1): "AUTO_READY", HOLD: "AUTO_LOITER", custom_mode(MAIN_AUTO, AUTO_MISSION): "AUTO_MISSION",
    custom_mode(MAIN_AUTO, AUTO_RTL): "AUTO_RTL", custom_mode(MAIN_ACRO): "ACRO", OFFBOARD: "OFFBOARD",
    custom_mode(MAIN_STAB): "STAB",
}
ROVER_TYPES = (apm.MAV_TYPE_GROUND_ROVER,)

STREAMS = {  # message id -> interval (µs): EKF_STATUS_REPORT is ArduPilot's; PX4 says the same in ESTIMATOR_STATUS
    apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 100_000,
    apm.MAVLINK_MSG_ID_ATTITUDE: 100_000,
    apm.MAVLINK_MSG_ID_GPS_RAW_INT: 500_000,
    apm.MAVLINK_MSG_ID_ESTIMATOR_STATUS: 500_000,
    apm.MAVLINK_MSG_ID_DISTANCE_SENSOR: 100_000,  # its distance sensors, as ArduPilot's (vehicle.companion.ranges)
}
STREAM_LEAD = 0.2  # s of setpoints before asking for Offboard: PX4 wants one fresher than COM_OF_LOSS_T
MODE_RETRY = 0.3  # s before a refused or unanswered Offboard request is sent again (the stream may be just starting)
MODE_TRIES = 6
YAW_P = 5.0  # RO_YAW_P of airframe 1069 (and the r1 rover): PX4's yaw loop, rad/s per rad of bearing error
STOP_SPEED = 1e-3  # m/s: "stand still facing this way" (a zero vector would mean bearing north)
MAX_LEAD = math.radians(60)  # the largest bearing offset a yaw-rate command becomes
ABOUT_DONE = math.radians(20)  # an about-turn is done this close to its bearing (RD_TRANS_DRV_TRN of airframe 1069)
ABOUT_TARGETS = 60  # ... and given up after this many targets (6 s at 10 Hz: a slow full turn)


def mode_name(mode: int | None) -> str:
    if mode is None:
        return "unknown"
    return MODE_NAMES.get(mode, f"PX4 mode {(mode >> 16) & 0xFF}.{(mode >> 24) & 0xFF}")


def rover_problem(m) -> str | None:
    """Why the PX4 whose HEARTBEAT is ``m`` cannot be driven by the companion, or None if it can."""
    if m.type in ROVER_TYPES:
        return None
    entry = apm.enums["MAV_TYPE"].get(m.type)
    name = entry.name.removeprefix("MAV_TYPE_") if entry else str(m.type)
    return f"the autopilot is PX4 for a {name}, not a PX4 rover"


def set_mode(enc: apm.MAVLink, sysid: int, compid: int, mode: int):
    """DO_SET_MODE as PX4 reads it: the custom-mode flag, then its main and sub mode."""
    return enc.command_long_encode(sysid, compid, apm.MAV_CMD_DO_SET_MODE, 0, apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                   (mode >> 16) & 0xFF, (mode >> 24) & 0xFF, 0, 0, 0, 0)


def bearing_lead(yaw_rate: float, period: float, yaw_p: float = YAW_P) -> float:
    """The bearing offset (rad, from the rover's heading) that makes PX4 turn at ``yaw_rate`` on average over one
    target ``period``: its yaw loop closes the offset exponentially with time constant 1/``yaw_p``, so over a period
    it turns ``lead * (1 - exp(-period * yaw_p))``; the lead asks for ``yaw_rate * period`` of that."""
    turned = 1.0 - math.exp(-period * yaw_p) if yaw_p > 0 else 1.0
    return max(-MAX_LEAD, min(MAX_LEAD, yaw_rate * period / turned))


def velocity_target(enc: apm.MAVLink, sysid: int, compid: int, speed: float, yaw_rate: float, period: float,
                    yaw_p: float = YAW_P):
    """One BODY_NED velocity target for the vehicle's (``speed``, ``yaw_rate``) (see the module docstring)."""
    lead = bearing_lead(yaw_rate, period, yaw_p)
    if speed < 0:  # no reverse in Offboard: turn toward where it wants to go and drive there forward
        lead, speed = math.pi + lead, -speed
    v = max(speed, STOP_SPEED)
    mask = 0b0000_1101_1100_0111  # use vx vy vz only (positions, accelerations, yaw, yaw rate ignored)
    return enc.set_position_target_local_ned_encode(0, sysid, compid, apm.MAV_FRAME_BODY_NED, mask, 0, 0, 0,
                                                    v * math.cos(lead), v * math.sin(lead), 0, 0, 0, 0, 0, 0)


def bearing_target(enc: apm.MAVLink, sysid: int, compid: int, bearing: float, speed: float = STOP_SPEED):
    """One LOCAL_NED velocity target along ``bearing`` (rad from north) at ``speed``: PX4 turns to it (on the spot
    when far off) and drives along it."""
    v = max(speed, STOP_SPEED)
    mask = 0b0000_1101_1100_0111  # use vx vy vz only
    return enc.set_position_target_local_ned_encode(0, sysid, compid, apm.MAV_FRAME_LOCAL_NED, mask, 0, 0, 0,
                                                    v * math.cos(bearing), v * math.sin(bearing), 0, 0, 0, 0, 0, 0)


def param_value(value: float, ptype: int) -> float:
    """A PARAM_VALUE's number as PX4 means it: an integer parameter's bits are in the float (bytewise)."""
    if ptype == apm.MAV_PARAM_TYPE_INT32:
        return float(struct.unpack("<i", struct.pack("<f", value))[0])
    if ptype == apm.MAV_PARAM_TYPE_UINT32:
        return float(struct.unpack("<I", struct.pack("<f", value))[0])
    return float(value)


def param_wire(value: float, ptype: int) -> float:
    """The float PARAM_SET carries for ``value`` of a parameter PX4 reported as ``ptype`` (bytewise for integers;
    PX4 drops a PARAM_SET whose type is not the parameter's own)."""
    if ptype in (apm.MAV_PARAM_TYPE_INT32, apm.MAV_PARAM_TYPE_UINT32):
        fmt = "<i" if ptype == apm.MAV_PARAM_TYPE_INT32 else "<I"
        return struct.unpack("<f", struct.pack(fmt, int(round(value))))[0]
    return float(value)
