"""What the companion knows of the autopilot, read from the autopilot's own messages, and the vehicle's readings
made of it (docs/architecture.md §11).

Reading and commanding are apart: this module only believes and remembers (which autopilot, its mode, its filtered
estimate, its parameters); ``vehicle.companion.autopilot`` decides what to send. Each message kind has one small
reader in ``READERS`` (as the lockstep bridge's ``Tap._NOTES``), so a new kind is a new line, not a branch.

The readings are the autopilot's own filtered estimate: LOCAL_POSITION_NED as the position fix, ATTITUDE as heading
and yaw rate, GPS_RAW_INT and the estimator's status for how far to trust it. The vehicle's estimator fuses them
exactly as it fuses a robot's sensors, so the trail and the return see one pose whatever the robot is.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion.rules import Rules, is_autopilot_heartbeat
from vehicle.io import Fix, Readings, Scan

LOST_AFTER = 3.0  # s of silence from the autopilot before it counts as lost
STALE = 0.5  # s: an estimate older than this is not used for speed or yaw rate
EKF_POS_HORIZ_REL, EKF_POS_HORIZ_ABS = 8, 16
STANDING = 0.1  # m/s: the autopilot's estimate says the rover stands below this


@dataclass
class Observed:
    """What the companion knows of the autopilot, from its own messages."""

    sysid: int | None = None
    compid: int = 1
    mav_type: int | None = None
    autopilot: int | None = None
    mode: int | None = None
    mode_at: float = -math.inf  # when the autopilot last said its mode (a HEARTBEAT, or accepting a request)
    armed: bool = False
    heard: float | None = None  # when the autopilot's last frame arrived
    position: tuple[float, float, float, float, float] | None = None  # (t, x, y, vx, vy)
    before: tuple[float, float, float, float, float] | None = None  # the estimate before ``position``
    attitude: tuple[float, float, float] | None = None  # (t, yaw, yaw rate)
    fix_type: int = 0
    h_acc: float | None = None  # m, from GPS_RAW_INT
    eph: float | None = None  # HDOP
    ekf_flags: int | None = None
    origin: tuple[float, float, float] | None = None  # (lat, lon, alt) of the EKF origin
    params: dict[str, float] = field(default_factory=dict)
    param_types: dict[str, int] = field(default_factory=dict)
    position_times: list[float] = field(default_factory=list)  # arrivals of LOCAL_POSITION_NED, recent ones

    def position_valid(self) -> bool:
        """Whether LOCAL_POSITION_NED means anything yet: the EKF reports a horizontal position (absolute once a
        GPS has a fix; relative will do on a rover without one). Before it, ArduPilot reports zeros."""
        if self.position is None:
            return False
        flags = self.ekf_flags
        if flags is None:
            return True
        if flags & EKF_POS_HORIZ_ABS:
            return True
        return bool(flags & EKF_POS_HORIZ_REL) and self.fix_type < 3

    def position_std(self) -> float:
        """1-sigma horizontal error of a fix: the receiver's own accuracy, else a guess from HDOP."""
        if self.h_acc:
            return min(20.0, max(0.05, self.h_acc))
        if self.eph:
            return min(20.0, max(0.1, 1.5 * self.eph))
        return 1.0

    def rate(self, t: float) -> float:
        """LOCAL_POSITION_NED per second over the last 2 s."""
        recent = [x for x in self.position_times if x > t - 2.0]
        self.position_times[:] = recent
        return len(recent) / 2.0

    def yaw(self) -> float | None:
        """The autopilot's last heading (rad, NED), None before its first ATTITUDE."""
        return self.attitude[1] if self.attitude is not None else None

    def lost(self, t: float) -> bool:
        """The autopilot never heard, or silent for LOST_AFTER."""
        return self.heard is None or t - self.heard > LOST_AFTER

    def ready(self) -> bool:
        """The autopilot has said who it is and where it is: the vehicle can boot on its estimate."""
        return self.sysid is not None and self.attitude is not None and self.position_valid()

    def pose(self) -> tuple[float, float, float]:
        """(x, y, yaw) of the autopilot's estimate (once ``ready``)."""
        assert self.position is not None and self.attitude is not None
        return self.position[1], self.position[2], self.attitude[1]

    def speed_along(self, t: float) -> tuple[float, float] | None:
        """The rover's speed along its heading (m/s, negative backward) and its rate of change (m/s/s, over the last
        two estimates) from the autopilot's fresh estimate, or None (none fresh)."""
        pos, before, att = self.position, self.before, self.attitude
        if pos is None or t - pos[0] > STALE or att is None:
            return None
        c, s = math.cos(att[1]), math.sin(att[1])
        v = pos[3] * c + pos[4] * s
        if before is None or not 0.0 < pos[0] - before[0] <= STALE:
            return v, 0.0
        return v, (v - (before[3] * c + before[4] * s)) / (pos[0] - before[0])

    def standing(self, t: float) -> bool:
        """The autopilot's fresh estimate says the rover stands (below STANDING)."""
        pos = self.position
        return pos is not None and t - pos[0] <= STALE and math.hypot(pos[3], pos[4]) < STANDING


# ----- one reader a message kind (the autopilot's own component only) -----------------------------------------------
def _heartbeat(s: Observed, m, t: float, rules: Rules) -> None:
    if not is_autopilot_heartbeat(m):  # (the autopilot's own system and component, yet not an autopilot speaking)
        return
    s.mav_type, s.autopilot = m.type, m.autopilot
    s.mode, s.armed = m.custom_mode, bool(m.base_mode & apm.MAV_MODE_FLAG_SAFETY_ARMED)
    s.mode_at = t


def _local_position(s: Observed, m, t: float, rules: Rules) -> None:
    s.before, s.position = s.position, (t, m.x, m.y, m.vx, m.vy)
    s.position_times.append(t)


def _attitude(s: Observed, m, t: float, rules: Rules) -> None:
    s.attitude = (t, m.yaw, m.yawspeed)


def _gps(s: Observed, m, t: float, rules: Rules) -> None:
    s.fix_type = m.fix_type
    s.eph = m.eph / 100 if m.eph != 65535 else None
    h_acc = getattr(m, "h_acc", 0)
    s.h_acc = h_acc / 1000 if h_acc else None


def _estimator(s: Observed, m, t: float, rules: Rules) -> None:
    if m.get_type() in rules.estimate_reports:
        s.ekf_flags = m.flags  # (the same bits: position horizontal relative 8, absolute 16)


def _origin(s: Observed, m, t: float, rules: Rules) -> None:
    s.origin = (m.latitude / 1e7, m.longitude / 1e7, m.altitude / 1000)


def _param(s: Observed, m, t: float, rules: Rules) -> None:
    name = param_name(m.param_id)
    s.params[name], s.param_types[name] = rules.param_value(m.param_value, m.param_type), m.param_type


READERS: dict[str, Callable[[Observed, object, float, Rules], None]] = {
    "HEARTBEAT": _heartbeat, "LOCAL_POSITION_NED": _local_position, "ATTITUDE": _attitude, "GPS_RAW_INT": _gps,
    "EKF_STATUS_REPORT": _estimator, "ESTIMATOR_STATUS": _estimator, "GPS_GLOBAL_ORIGIN": _origin,
    "PARAM_VALUE": _param,
}


def believe(s: Observed, m, t: float, rules: Rules) -> bool:
    """Take what the autopilot's own message ``m`` says into ``s``; False: not the autopilot's own (another system,
    or another component of its system), nothing believed."""
    if s.sysid is None or m.get_srcSystem() != s.sysid or m.get_srcComponent() != s.compid:
        return False
    s.heard = t
    reader = READERS.get(m.get_type())
    if reader is not None:
        reader(s, m, t, rules)
    return True


def param_name(raw) -> str:
    """A PARAM_VALUE's ``param_id`` as text (bytes or str, NUL-padded)."""
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return raw.split("\x00", 1)[0]


class EstimateFeed:
    """The vehicle's readings from what is observed: each new estimate once, as a fix or a heading."""

    def __init__(self) -> None:
        self.last_position_read: float | None = None
        self.last_attitude_read: float | None = None

    def read(self, s: Observed, t: float, scan: Scan | None) -> Readings:
        """This tick's readings: each new estimate once, as a fix or a heading; speed and yaw rate from the
        freshest one (zero once it is stale: a lost autopilot must not be dead-reckoned onward); ``scan`` the range
        data heard since the last tick (None: none, as from a rover without range sensors)."""
        fix = heading = None
        speed = yaw_rate = 0.0
        att = s.attitude
        if att is not None and t - att[0] <= STALE:
            yaw_rate = att[2]
            if att[0] != self.last_attitude_read:
                heading, self.last_attitude_read = att[1], att[0]
        pos = s.position
        if pos is not None and t - pos[0] <= STALE and s.position_valid():
            yaw = att[1] if att is not None else 0.0
            speed = pos[3] * math.cos(yaw) + pos[4] * math.sin(yaw)
            if pos[0] != self.last_position_read:
                fix, self.last_position_read = Fix(pos[1], pos[2], s.position_std()), pos[0]
        return Readings(t, speed, yaw_rate, fix, heading, 0.02, None, scan)
