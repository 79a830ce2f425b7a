"""An ArduPilot Rover or a PX4 rover as the robot: a ``RobotDriver`` over MAVLink instead of wheels and sensors
(docs/architecture.md §11, §11.2).

The driver learns which autopilot it drives from the first HEARTBEAT (``autopilot`` 3 ArduPilot, 12 PX4) and
takes that autopilot's rules (``ArduPilotRules``, ``PX4Rules``: mode numbers, how a mode is asked for, the targets,
the streams, parameter encoding); everything else (readings, engagement, the watch for modes it did not command,
the keepalive) is one code for both. What follows is ArduPilot's story; PX4's is in ``vehicle.companion.px4``.

Readings come from the autopilot's own filtered estimate: LOCAL_POSITION_NED (asked for at 10 Hz with
MAV_CMD_SET_MESSAGE_INTERVAL) as the position fix, ATTITUDE as heading and yaw rate, GPS_RAW_INT and
EKF_STATUS_REPORT for how far to trust it. The vehicle's estimator fuses them exactly as it fuses a robot's
sensors, so the trail and the return see one pose whatever the robot is. The rover's range data (DISTANCE_SENSOR,
asked for at 10 Hz beside the estimate, and OBSTACLE_DISTANCE; from the autopilot or from any other component of its
system, such as a lidar driver) is the vehicle's range sensor (``vehicle.companion.ranges``): the return keeps its
body off what it sees, as the native rover's does.

Commands reach the autopilot only while a return holds the lease (``engage``): the companion switches it to
GUIDED and streams SET_POSITION_TARGET_LOCAL_NED velocity and turn-rate targets at 10 Hz. Rover stops a velocity
target 3 s after the last one, which makes the stream a dead-man: a companion that dies mid-return leaves a rover
that stops. Position targets never time out, so none is ever sent. On ``release`` it brakes and then switches to
HOLD, unless someone else already chose a mode: Rover's HOLD sets the throttle to zero and lets the rover roll
(beside the firmware's own physics, 3.2 m from 1.9 m/s), so the companion first streams zero-velocity targets, which
the speed controller brakes to at its deceleration limit, until the rover stands (DESIGN §6.2; PX4 alike, zero
Offboard setpoints before Hold, which stops 1.5-2 cm shorter than Hold at once: ``PX4Rules.brakes``). While
engaged, a mode change it did not ask for (the pilot's RC switch, the autopilot's own failsafe, a ground station) is
reported by ``tick``: the return ends rather than fight the pilot.

The backstop: a HEARTBEAT from a ground-station system id (the autopilot's MAV_GCS_SYSID, read from it) at 1 Hz,
sent only by a loop that ticks and is healthy. Ground stations' own heartbeats never reach the autopilot, so a
dead or hung companion ends in the autopilot's GCS failsafe (FS_GCS_ENABLE, FS_ACTION).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion import px4
from vehicle.companion.governor import Governor
from vehicle.companion.ranges import KINDS as RANGE_KINDS
from vehicle.companion.ranges import RangeSensors
from vehicle.io import Fix, Readings

# ArduPilot Rover's mode numbers (Rover/mode.h)
ROVER_MODES = {0: "MANUAL", 1: "ACRO", 3: "STEERING", 4: "HOLD", 5: "LOITER", 6: "FOLLOW", 7: "SIMPLE", 8: "DOCK",
               9: "CIRCLE", 10: "AUTO", 11: "RTL", 12: "SMART_RTL", 15: "GUIDED", 16: "INITIALISING"}
GUIDED, HOLD = 15, 4
ROVER_TYPES = (apm.MAV_TYPE_GROUND_ROVER, apm.MAV_TYPE_SURFACE_BOAT)  # the Rover firmware drives both

COMPANION_COMPID = apm.MAV_COMP_ID_ONBOARD_COMPUTER
TARGET_PERIOD = 0.1  # s between velocity targets (the autopilot drops a stream silent for 3 s)
KEEPALIVE_PERIOD = 1.0  # s between backstop heartbeats
MODE_RETRY = 1.0  # s before a mode request not yet seen in the heartbeat is sent again
MODE_TRIES = 4  # ... and how often, before the return gives up on the autopilot
LOST_AFTER = 3.0  # s of silence from the autopilot before it counts as lost
STALE = 0.5  # s: an estimate older than this is not used for speed or yaw rate
STREAMS = {  # message id -> interval (µs) the companion needs
    apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 100_000,
    apm.MAVLINK_MSG_ID_ATTITUDE: 100_000,
    apm.MAVLINK_MSG_ID_GPS_RAW_INT: 500_000,
    apm.MAVLINK_MSG_ID_EKF_STATUS_REPORT: 500_000,
    apm.MAVLINK_MSG_ID_DISTANCE_SENSOR: 100_000,  # every rangefinder and proximity sector (none: nothing sent)
}
STREAM_CHECK = 5.0  # s between checks that the position stream still runs at its rate
GCS_SYSID_PARAMS = ("MAV_GCS_SYSID", "SYSID_MYGCS")  # ArduPilot 4.7+, and before
CREEP = 0.3  # m/s: a rover that steers like a car turns "in place" by creeping, or it never turns at all
EKF_POS_HORIZ_REL, EKF_POS_HORIZ_ABS = 8, 16
STANDING = 0.1  # m/s: the autopilot's estimate says the rover stands below this
SLOWING = 0.3  # m/s: a command this much slower than the last target's is sent at once
BRAKE_MAX_S = 5.0  # s: zero targets at most this long before HOLD anyway (a rover on a slope, a noisy estimate)


def rover_problem(m) -> str | None:
    """Why the autopilot whose HEARTBEAT is ``m`` cannot be driven by the companion, or None if it can."""
    if m.autopilot == apm.MAV_AUTOPILOT_PX4:
        return px4.rover_problem(m)
    if m.autopilot != apm.MAV_AUTOPILOT_ARDUPILOTMEGA:
        entry = apm.enums["MAV_AUTOPILOT"].get(m.autopilot)
        name = entry.name.removeprefix("MAV_AUTOPILOT_") if entry else str(m.autopilot)
        return f"the autopilot is {name}, not ArduPilot or PX4"
    if m.type not in ROVER_TYPES:
        entry = apm.enums["MAV_TYPE"].get(m.type)
        name = entry.name.removeprefix("MAV_TYPE_") if entry else str(m.type)
        return f"the autopilot is ArduPilot for a {name}, not ArduPilot Rover"
    return None


def is_autopilot_heartbeat(m) -> bool:
    return m.get_type() == "HEARTBEAT" and m.autopilot != apm.MAV_AUTOPILOT_INVALID


class ArduPilotRules:
    """How the companion drives ArduPilot Rover (the module docstring): GUIDED, then velocity and turn-rate targets
    in the body frame, which the firmware executes for 3 s each; HOLD to stop; parameters cast to float."""

    name = "ArduPilot Rover"
    autopilot = apm.MAV_AUTOPILOT_ARDUPILOTMEGA
    drive, hold = GUIDED, HOLD
    lead: float | None = None  # targets only once in GUIDED: the firmware needs no stream before the switch
    mode_retry, mode_tries = MODE_RETRY, MODE_TRIES
    streams = STREAMS
    gcs_sysid_params = GCS_SYSID_PARAMS
    stop_holds = False  # the dead-man's stop: a zero target, staying in GUIDED
    brakes = True  # a return released to HOLD brakes first with zero targets (HOLD alone coasts)

    @staticmethod
    def mode_name(mode: int | None) -> str:
        return "unknown" if mode is None else ROVER_MODES.get(mode, f"mode {mode}")

    @staticmethod
    def set_mode(enc: apm.MAVLink, sysid: int, compid: int, mode: int):
        return enc.command_long_encode(sysid, compid, apm.MAV_CMD_DO_SET_MODE, 0,
                                       apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode, 0, 0, 0, 0, 0)

    @staticmethod
    def param_value(value: float, ptype: int) -> float:
        return float(value)

    @staticmethod
    def param_wire(value: float, ptype: int) -> float:
        return float(value)


class PX4Rules:
    """How the companion drives a PX4 rover (``vehicle.companion.px4``): a velocity stream from the moment a return
    holds the lease, Offboard asked for once it runs, Hold (AUTO_LOITER) to stop; parameters bytewise."""

    name = "PX4 rover"
    autopilot = apm.MAV_AUTOPILOT_PX4
    drive, hold = px4.OFFBOARD, px4.HOLD
    lead: float | None = px4.STREAM_LEAD
    mode_retry, mode_tries = px4.MODE_RETRY, px4.MODE_TRIES
    streams = px4.STREAMS
    gcs_sysid_params: tuple[str, ...] = ()  # PX4 counts any GCS-type HEARTBEAT: no system id to match
    stop_holds = True  # the dead-man's stop: Hold (a stream of stops would also keep a dead owner's Offboard alive)
    brakes = True  # a return released brakes with zero Offboard setpoints, then Hold, which stops shorter than Hold
    # at once. Measured beside PX4 (our plant): from 1 m/s, 0.340-0.345 m against Hold's 0.356-0.364 on the hard edge
    # (tests/test_companion_stop_lockstep.py, three runs each), 0.337-0.344 against 0.350-0.366 in the tunnel (four
    # runs each, two of 100 s), with one link loss in every run. (An earlier tree lost the link a second time in the
    # real-PX4 run of tests/test_px4_companion.py after the operator resumed, so Hold stayed for 2 cm; since the
    # operator drives home after a return (issue 41) no run lost it twice.)
    mode_name = staticmethod(px4.mode_name)
    set_mode = staticmethod(px4.set_mode)
    param_value = staticmethod(px4.param_value)
    param_wire = staticmethod(px4.param_wire)


RULES: dict[int, type[ArduPilotRules] | type[PX4Rules]] = {apm.MAV_AUTOPILOT_PX4: PX4Rules}


def rules_for(autopilot: int) -> type[ArduPilotRules] | type[PX4Rules]:
    """The rules for the autopilot a HEARTBEAT names (ArduPilot's for anything not PX4: ``rover_problem`` says
    whether it can be driven at all)."""
    return RULES.get(autopilot, ArduPilotRules)


@dataclass
class Observed:
    """What the companion knows of the autopilot, from its own messages."""

    sysid: int | None = None
    compid: int = 1
    mav_type: int | None = None
    autopilot: int | None = None
    mode: int | None = None
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


class AutopilotDriver:
    """The ``RobotDriver`` over MAVLink (see the module docstring). Frames for the autopilot go to ``send``."""

    mav_type = apm.MAV_TYPE_ONBOARD_CONTROLLER  # the companion's own HEARTBEAT (docs/architecture.md §11)

    def __init__(self, send: Callable[[bytes], None], pivots: bool = False) -> None:
        """``pivots``: the rover turns on the spot (skid steering); otherwise a turn in place creeps."""
        self.send = send
        self.pivots = pivots
        self.rules: type[ArduPilotRules] | type[PX4Rules] = ArduPilotRules  # until the autopilot's HEARTBEAT says
        self.seen = Observed()
        self.enc: apm.MAVLink | None = None  # as (the autopilot's sysid, 191), once that sysid is known
        self.keepalive_enc = apm.MAVLink(None, 255, COMPANION_COMPID)
        self.command_out = (0.0, 0.0)
        self.direction = 1.0  # the sign of the last speed driven: a creeping turn keeps going that way
        self.engaged = False
        self.confirmed = False  # GUIDED seen (or acknowledged) since engaging
        self.mode_at_engage: int | None = None
        self.wanted: int | None = None  # a mode asked for and not yet seen
        self.asked_at = -math.inf
        self.tries = 0
        self.refused: str | None = None  # the autopilot's answer to a mode request it refused
        self.next_target = -math.inf
        self.switch_at: float | None = None  # when to ask for the drive mode, once the stream runs (PX4)
        self.mode_at = -math.inf  # when the autopilot last said its mode (a HEARTBEAT, or accepting a request)
        self.yaw_p = px4.YAW_P  # PX4's RO_YAW_P, once read: how its yaw loop answers a bearing
        self.about: float | None = None  # PX4: the NED bearing of an about-turn in place of a backward drive
        self.about_at = 0  # ... begun at this target
        self.targets = 0  # PX4 targets sent
        self.next_keepalive = -math.inf
        self.next_stream_check = -math.inf
        self.streams_asked = False
        self.last_position_read: float | None = None
        self.last_attitude_read: float | None = None
        self.keepalives = 0  # sent, for the record
        self.governor = Governor()  # ArduPilot's speed targets, its loop's overshoot taken off
        self.sent_command = 0.0  # the speed command the last target carried (before the governor)
        self.braking_since: float | None = None  # released to HOLD, streaming zero targets until the rover stands
        self.ranges = RangeSensors()  # the rover's range data, heard from any component of the autopilot's system

    # ----- what the autopilot says ---------------------------------------------------------------------------
    def observe(self, m, t: float) -> None:
        """One message from the autopilot side (any component; only the autopilot's own are believed)."""
        s = self.seen
        kind = m.get_type()
        if kind == "BAD_DATA":
            return
        if is_autopilot_heartbeat(m):
            if s.sysid is None:
                s.sysid, s.compid = m.get_srcSystem(), m.get_srcComponent()
                self.enc = apm.MAVLink(None, s.sysid, COMPANION_COMPID)
                self.rules = rules_for(m.autopilot)
            if (m.get_srcSystem(), m.get_srcComponent()) == (s.sysid, s.compid):
                s.mav_type, s.autopilot = m.type, m.autopilot
                s.mode, s.armed = m.custom_mode, bool(m.base_mode & apm.MAV_MODE_FLAG_SAFETY_ARMED)
                self.mode_at = t
        if kind in RANGE_KINDS and s.sysid is not None and m.get_srcSystem() == s.sysid:
            # the autopilot's rangefinders, or a lidar driver's sectors: another component of the vehicle counts
            self.ranges.heard(m, t, s.attitude[1] if s.attitude is not None else None)
        if s.sysid is None or m.get_srcSystem() != s.sysid or m.get_srcComponent() != s.compid:
            return
        s.heard = t
        if kind == "LOCAL_POSITION_NED":
            s.before, s.position = s.position, (t, m.x, m.y, m.vx, m.vy)
            s.position_times.append(t)
        elif kind == "ATTITUDE":
            s.attitude = (t, m.yaw, m.yawspeed)
        elif kind == "GPS_RAW_INT":
            s.fix_type = m.fix_type
            s.eph = m.eph / 100 if m.eph != 65535 else None
            h_acc = getattr(m, "h_acc", 0)
            s.h_acc = h_acc / 1000 if h_acc else None
        elif kind == "EKF_STATUS_REPORT" or (kind == "ESTIMATOR_STATUS" and self.rules is PX4Rules):
            s.ekf_flags = m.flags  # (the same bits: position horizontal relative 8, absolute 16)
        elif kind == "GPS_GLOBAL_ORIGIN":
            s.origin = (m.latitude / 1e7, m.longitude / 1e7, m.altitude / 1000)
        elif kind == "PARAM_VALUE":
            name = _param_name(m.param_id)
            s.params[name], s.param_types[name] = self.rules.param_value(m.param_value, m.param_type), m.param_type
            if name == "RO_YAW_P" and s.params[name] > 0:
                self.yaw_p = s.params[name]
        elif kind == "COMMAND_ACK" and m.command == apm.MAV_CMD_DO_SET_MODE and self._for_me(m):
            if m.result == apm.MAV_RESULT_ACCEPTED and self.wanted is not None:
                s.mode, self.mode_at = self.wanted, t  # set before the answer left: the next heartbeat shows it
            elif m.result not in (apm.MAV_RESULT_ACCEPTED, apm.MAV_RESULT_IN_PROGRESS) and self.wanted is not None \
                    and not (self.rules.lead is not None and self.tries < self.rules.mode_tries):
                # (PX4 refuses Offboard until its check has seen the stream: asked again, up to its tries)
                entry = apm.enums["MAV_RESULT"].get(m.result)
                self.refused = (f"the autopilot refused {self.mode_name(self.wanted)} "
                                f"({entry.name.removeprefix('MAV_RESULT_') if entry else m.result})")

    def _for_me(self, m) -> bool:
        return m.target_system in (0, self.seen.sysid) and m.target_component in (0, COMPANION_COMPID)

    @property
    def armed(self) -> bool:
        return self.seen.armed

    def lost(self, t: float) -> bool:
        return self.seen.heard is None or t - self.seen.heard > LOST_AFTER

    def ready(self) -> bool:
        """The autopilot has said who it is and where it is: the vehicle can boot on its estimate."""
        s = self.seen
        return s.sysid is not None and s.attitude is not None and s.position_valid()

    def pose(self) -> tuple[float, float, float]:
        s = self.seen
        assert s.position is not None and s.attitude is not None
        return s.position[1], s.position[2], s.attitude[1]

    # ----- RobotDriver -----------------------------------------------------------------------------------------
    def read(self, t: float, dt: float) -> Readings:
        """This tick's readings: each new estimate once, as a fix or a heading; speed and yaw rate from the
        freshest one (zero once it is stale: a lost autopilot must not be dead-reckoned onward); the range data
        heard since the last tick as a scan (None: none, as from a rover without range sensors)."""
        s = self.seen
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
        return Readings(t, speed, yaw_rate, fix, heading, 0.02, None, self.ranges.scan(t))

    def command(self, speed: float, yaw_rate: float) -> None:
        """The vehicle's command this tick; it reaches the autopilot only while engaged (see ``tick``)."""
        self.command_out = (speed, yaw_rate)
        if abs(speed) > 0.05:
            self.direction = math.copysign(1.0, speed)

    # ----- the return's hands on the autopilot -----------------------------------------------------------------
    def engage(self, t: float) -> None:
        """A return holds the lease (and the autopilot is armed: a disarmed rover's mode is its pilot's): GUIDED,
        then targets (PX4: targets, then Offboard once they run)."""
        r = self.rules
        self.engaged, self.refused = True, None
        self.braking_since = None
        self.mode_at_engage = self.seen.mode
        self.switch_at = self.about = None
        if r.lead is None:
            self.confirmed = self.seen.mode == r.drive
            if not self.confirmed:
                self._ask(r.drive, t)
        else:
            # PX4: the stream first, then Offboard asked for even if the owner's Offboard still shows: its stream
            # died with the link, and PX4 may be leaving Offboard for Hold right now (COM_OF_LOSS_T), which its
            # heartbeat says up to a second later. Confirmed once PX4 has answered the companion's own request
            self.confirmed = False
            self.switch_at, self.next_target = t + r.lead, t

    def release(self, t: float, hold: bool) -> None:
        """The return no longer holds the lease: no more of its targets; HOLD if ``hold`` and the autopilot is
        still in the mode the companion put it in (a mode someone else chose is theirs). ArduPilot: zero-velocity
        targets first, until the rover stands (``_brake``), then HOLD."""
        self.engaged = False
        self.wanted = self.switch_at = None
        if hold and self.seen.mode == self.rules.drive:
            if self.rules.brakes:
                self.braking_since, self.next_target = t, t
                self._brake(t)
            else:
                self._ask(self.rules.hold, t)

    def speed_along(self, t: float) -> tuple[float, float] | None:
        """The rover's speed along its heading (m/s, negative backward) and its rate of change (m/s/s, over the last
        two estimates) from the autopilot's fresh estimate, or None (none fresh)."""
        pos, before, att = self.seen.position, self.seen.before, self.seen.attitude
        if pos is None or t - pos[0] > STALE or att is None:
            return None
        c, s = math.cos(att[1]), math.sin(att[1])
        v = pos[3] * c + pos[4] * s
        if before is None or not 0.0 < pos[0] - before[0] <= STALE:
            return v, 0.0
        return v, (v - (before[3] * c + before[4] * s)) / (pos[0] - before[0])

    def standing(self, t: float) -> bool:
        """The autopilot's fresh estimate says the rover stands (below STANDING)."""
        pos = self.seen.position
        return pos is not None and t - pos[0] <= STALE and math.hypot(pos[3], pos[4]) < STANDING

    def _brake(self, t: float) -> None:
        """One tick of the brake after a return: a zero target every TARGET_PERIOD while the rover still moves
        (at most BRAKE_MAX_S), then HOLD. A mode someone else chose ends it (theirs), and so does the owner driving
        again (``stop_braking``)."""
        since = self.braking_since
        if since is None:
            return
        if self.seen.mode != self.rules.drive:
            self.braking_since = None
            return
        if self.standing(t) or t - since >= BRAKE_MAX_S:
            self.braking_since = None
            self._ask(self.rules.hold, t)
            return
        if t >= self.next_target:
            self.next_target = t + TARGET_PERIOD
            self._zero_target()

    def stop_braking(self) -> None:
        """The owner drives the autopilot again: its targets, not the brake's."""
        self.braking_since = None

    def _ask(self, mode: int, t: float) -> None:
        self.wanted, self.tries, self.refused = mode, 0, None
        self._request_mode(t)

    def _request_mode(self, t: float) -> None:
        if self.enc is None or self.wanted is None:
            return
        self.asked_at, self.tries = t, self.tries + 1
        self.send_message(self.rules.set_mode(self.enc, self.seen.sysid, self.seen.compid, self.wanted))

    def tick(self, t: float, healthy: bool) -> str | None:
        """Send what is due (keepalive, stream requests, mode requests, targets) and say why the return lost the
        autopilot, if it did this tick (None: it did not)."""
        if self.enc is None or self.lost(t):
            return None
        if healthy and t >= self.next_keepalive:
            self.next_keepalive = t + KEEPALIVE_PERIOD
            self._keepalive()
        if t >= self.next_stream_check:
            self._check_streams(t)
        s, r = self.seen, self.rules
        if self.wanted is not None:
            if s.mode == self.wanted and (r.lead is None or self.mode_at >= self.asked_at):
                # (PX4: said after the request, so a mode it was leaving when asked does not count)
                self.wanted = None
            elif self.refused is not None or (t - self.asked_at >= r.mode_retry and self.tries >= r.mode_tries):
                why = self.refused or f"the autopilot did not switch to {self.mode_name(self.wanted)}"
                self.wanted = None
                if self.engaged:
                    return why
            elif t - self.asked_at >= r.mode_retry:
                self._request_mode(t)
        if not self.engaged:
            self._brake(t)
            return None
        if not s.armed:
            return "the autopilot was disarmed, not by the companion: return ended"
        if s.mode == r.drive and (r.lead is None or (self.switch_at is None and self.wanted is None)):
            self.confirmed = True
        elif s.mode is not None and (self.confirmed or not self._unconfirmed_ok(s.mode)):
            return f"the autopilot switched to {self.mode_name(s.mode)}, not by the companion: return ended"
        streaming = s.mode == r.drive or r.lead is not None  # PX4: the stream runs before, and into, Offboard
        # a command to slow down (the approach speed, heard again) goes out at once, not up to a period later
        slowing = abs(self.command_out[0]) < abs(self.sent_command) - SLOWING
        if streaming and (t >= self.next_target or slowing):
            self.next_target = t + TARGET_PERIOD
            self._target(t)
        if self.switch_at is not None and t >= self.switch_at:
            self.switch_at = None
            self._ask(r.drive, t)
        return None

    def _unconfirmed_ok(self, mode: int) -> bool:
        """Whether ``mode``, seen before the autopilot confirmed the companion's drive mode, is no one's choice:
        the mode the return found (ArduPilot), or also PX4's Offboard and the Hold its Offboard loss of the owner's
        dead stream leads to (PX4)."""
        if mode == self.mode_at_engage:
            return True
        return self.rules.lead is not None and mode in (self.rules.drive, self.rules.hold)

    def mode_name(self, mode: int | None) -> str:
        """``mode`` as the autopilot driven names it."""
        return self.rules.mode_name(mode)

    def _target(self, t: float) -> None:
        """One velocity + turn-rate target in the body frame (position, acceleration and yaw ignored; PX4: a speed
        and a bearing, ``px4.velocity_target``). ArduPilot's speed is governed (``Governor``): its speed loop's
        overshoot, foreseen, is taken off the target."""
        assert self.enc is not None
        speed, yaw_rate = self.command_out
        self.sent_command = speed
        if self.rules is PX4Rules:
            self._px4_target(speed, yaw_rate)
            return
        along = self.speed_along(t)
        speed = speed if along is None else self.governor.target(speed, *along)
        if not self.pivots and abs(speed) < 0.05 and abs(yaw_rate) > 0.05:
            speed = CREEP * self.direction
        mask = 0b0000_0101_1100_0111  # ignore x y z, ax ay az, yaw: use vx vy vz and yaw rate
        self.send_message(self.enc.set_position_target_local_ned_encode(
            0, self.seen.sysid, self.seen.compid, apm.MAV_FRAME_BODY_NED, mask, 0, 0, 0, speed, 0, 0, 0, 0, 0, 0,
            yaw_rate))

    def resume(self, t: float) -> None:
        """Back to the drive mode the owner was driving in (PX4: Offboard, after a Hold that nobody on the ground
        asked for; ``Companion._resume_drive``)."""
        self._ask(self.rules.drive, t)

    def _px4_target(self, speed: float, yaw_rate: float) -> None:
        """PX4's target for the vehicle's command: a speed and a bearing ahead of the turn asked for; a backward
        command an about-turn to the heading behind, kept until it is done or the command is forward (or nothing)
        again (``vehicle.companion.px4``). While it lasts the navigator's own turns are not passed on: they steer a
        tail that PX4 is turning away (measured: a rover that stood stuck for 15 s, the navigator turning it back
        toward a route it was pivoting to)."""
        s = self.seen
        yaw = s.attitude[1] if s.attitude is not None else None
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
            self.send_message(px4.bearing_target(self.enc, s.sysid, s.compid, self.about))
        else:
            self.send_message(px4.velocity_target(self.enc, s.sysid, s.compid, speed, yaw_rate, TARGET_PERIOD,
                                                  self.yaw_p))

    def stop(self, t: float = 0.0) -> bool:
        """A zero-velocity target: the rover stops where it is and stays in GUIDED, so a return that follows
        drives at once, with no mode switch (the companion's dead-man over the owner's drive, ``Companion``).
        False: nothing sent (the autopilot is not in GUIDED, or not known yet).

        PX4: Hold (AUTO_LOITER) instead, asked for at ``t``. Offboard needs a stream, so standing in Offboard would
        mean the companion streaming stops in the owner's name, racing the owner's own setpoints when it speaks
        again and keeping an Offboard alive that PX4 would otherwise end itself after COM_OF_LOSS_T (for the
        same Hold: COM_OBL_RC_ACT). The return that follows streams first and switches to Offboard, a fifth of a
        second."""
        if self.enc is None or self.seen.mode != self.rules.drive:
            return False
        if self.rules.stop_holds:
            if self.wanted != self.rules.hold:
                self._ask(self.rules.hold, t)
            return True
        self._zero_target()
        return True

    def _zero_target(self) -> None:
        """A zero velocity and turn-rate target (ArduPilot, GUIDED; PX4, Offboard): the rover brakes to a stand."""
        assert self.enc is not None
        if self.rules is PX4Rules:
            self._px4_target(0.0, 0.0)
            return
        mask = 0b0000_0101_1100_0111  # as ``_target``: velocity and yaw rate used, all zero
        self.send_message(self.enc.set_position_target_local_ned_encode(
            0, self.seen.sysid, self.seen.compid, apm.MAV_FRAME_BODY_NED, mask, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0))

    def _keepalive(self) -> None:
        s = self.seen
        gcs = next((int(s.params[p]) for p in self.rules.gcs_sysid_params if p in s.params), 255)
        if not 1 <= gcs <= 255:
            gcs = 255
        self.keepalive_enc.srcSystem = gcs
        self.send_message(self.keepalive_enc.heartbeat_encode(apm.MAV_TYPE_GCS, apm.MAV_AUTOPILOT_INVALID, 0, 0,
                                                       apm.MAV_STATE_ACTIVE), self.keepalive_enc)
        self.keepalives += 1

    def _check_streams(self, t: float) -> None:
        """Ask for the estimate's streams at first contact and again whenever the position stream has slowed (a
        ground station's REQUEST_DATA_STREAM resets the autopilot's rates on this very channel); ask for the EKF
        origin and the ground-station system id until they are known."""
        self.next_stream_check = t + STREAM_CHECK
        s = self.seen
        assert self.enc is not None and s.sysid is not None
        streams = self.rules.streams
        wanted = 0.8 * 1e6 / streams[apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED]
        if not self.streams_asked or s.rate(t) < wanted:
            for msgid, interval in streams.items():
                self.send_message(self.enc.command_long_encode(s.sysid, s.compid, apm.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                                        msgid, interval, 0, 0, 0, 0, 0))
            self.streams_asked = True
        if s.origin is None:
            self.send_message(self.enc.command_long_encode(s.sysid, s.compid, apm.MAV_CMD_REQUEST_MESSAGE, 0,
                                                    apm.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 0, 0, 0, 0, 0, 0))
        asks = self.rules.gcs_sysid_params if self.rules is ArduPilotRules else ("RO_YAW_P",)
        if not any(p in s.params for p in asks):
            for name in asks:
                self.send_message(self.enc.param_request_read_encode(s.sysid, s.compid, name.encode(), -1))

    def send_message(self, msg, enc: apm.MAVLink | None = None) -> None:
        """One message to the autopilot, as the companion (or through ``enc``, as the keepalive's sender)."""
        enc = enc or self.enc
        assert enc is not None
        self.send(bytes(msg.pack(enc)))
        enc.seq = (enc.seq + 1) % 256


def mode_name(mode: int | None) -> str:
    return "unknown" if mode is None else ROVER_MODES.get(mode, f"mode {mode}")


def _param_name(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return raw.split("\x00", 1)[0]
