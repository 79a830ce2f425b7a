"""The scripted operator of a firmware run: a person at a ground station flying an ArduPilot rover in GUIDED.

It is the firmware's counterpart of ``sim.operator.Operator`` and knows only what reached it over the radio. It
sends a GCS heartbeat every second (what keeps the firmware's GCS failsafe quiet, and nothing else does), asks for
the local position and the attitude at 5 Hz, switches to GUIDED and arms (retrying each second until the heartbeat
shows it), then drives the scenario route as the native operator drives its rover, so that a comparison of the two
is one of returns, not of drivers: the same waypoints, each steered at straight from where the telemetry shows the
rover, the next once it is within ``WAYPOINT_RADIUS``, the leg's speed, and the same turn on the spot where the
heading is far off (``drive_setpoint``, which also slows before each corner). GUIDED takes that as a GCS joystick
script sends it, streamed at the native station's 10 Hz: a NED velocity (SET_POSITION_TARGET_LOCAL_NED, velocity
only: the firmware holds the heading of the velocity and its speed) or, to turn on the spot, a heading alone (the
firmware turns a skid-steered rover in place to it). Every waypoint of a generated world lies ``WAYPOINT_RADIUS``
beyond its corner so that this steering turns on the corner itself (``sim.worlds.build.waypoints``); the GUIDED
position targets this operator used to send, a carrot on the line between waypoints, cut door jambs on that line.
ArduPilot drops a velocity target not renewed for 3 s ("target not received last 3secs, stopping"), where the native
rover's dead-man is 0.5 s: a rover whose uplink dies keeps its last heading and speed that much longer, which is
the real firmware's and is what it does to a real operator.

When its picture freezes it keeps its heartbeat going and lets go of its stick (``_hold_still``). When it hears the
rover again and sees the firmware's failsafe has done its work (the rover in HOLD, or at rest in RTL/SMART_RTL for
``REST_S``), it takes control again (GUIDED) and drives the resume route, picked up as the native operator picks it
up (``Leg.join``: at the leg the rover is on, never back into the dead zone for a waypoint the return brought it
past); like the native operator it gives up a waypoint after ``attempts`` losses on the way to it.

Positions: the scenario route is in the world frame (x north, y east); the firmware's LOCAL_POSITION_NED is
relative to its EKF origin, where the rover stood when it got its first fix, i.e. the scenario's start.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from sim.station_script import WAYPOINT_RADIUS, Leg, ScriptedStation
from vehicle.navigation import TURN_IN_PLACE

GCS_SYSID, GCS_COMPID = 255, 190
STALE_TELEMETRY = 1.5  # s: no position report for this long and the picture has frozen
RETRY_S = 1.0
REST_S = 2.0  # s at rest in a return mode before the operator takes over again
REST_SPEED = 0.1  # m/s
GUIDED, HOLD, RTL, SMART_RTL = 15, 4, 11, 12
RETURN_MODES = frozenset((HOLD, RTL, SMART_RTL))
POSITION_ONLY = 0x0DF8  # SET_POSITION_TARGET type mask: x, y, z used; velocity, acceleration, yaw, yaw rate not
VELOCITY_ONLY = 0x0DC7  # ... vx, vy, vz used: ArduPilot Rover's GUIDED drives the velocity's heading at its speed
HEADING_ONLY = 0x09FF  # ... yaw used: a skid-steered rover turns on the spot to it (GUIDED, speed 0)
STOPPED = 0x05C7  # ... velocity and yaw rate used, all zero: GUIDED stops (the native station's zero stick)
LOCAL_POSITION_INTERVAL_US = 200_000
ATTITUDE_INTERVAL_US = 200_000  # its heading, which the native vehicle reads aboard, reaches the operator here
STICK_PERIOD = 0.1  # s: the drive is streamed as the native station streams its stick (gcs.station.TELEOP_PERIOD)
APPROACH_GAIN = 0.6  # 1/s: speed <= 0.6 * distance to the turn + APPROACH_FLOOR on the last metres before it
APPROACH_FLOOR = 0.2  # m/s


def drive_setpoint(position: tuple[float, float], yaw: float | None, waypoint: tuple[float, float],
                   speed: float) -> tuple[float, float]:
    """(bearing, speed) the native rover drives toward ``waypoint`` at the leg's ``speed``: the native operator's
    velocity (straight at the waypoint: ``sim.operator.Operator._drive``) as its vehicle executes it
    (``vehicle.teleop.velocity_to_command``: only the part along the heading, and none while the heading is more
    than TURN_IN_PLACE off, where it turns on the spot first). Speed 0 with a bearing: turn to it in place. ``yaw``
    None (no heading heard yet): the speed as asked.

    One care more than the native operator's, which slows on the last metres to the waypoint itself: this one slows
    on the last metres to where it turns, WAYPOINT_RADIUS short of the waypoint (the corner of the way: the next
    waypoint is taken there), to APPROACH_FLOOR on the corner. The native vehicle turns at once on its own 50 Hz
    heading; an autopilot's operator sees the rover at 5 Hz through the radio and the autopilot brakes by its own
    tuning, so at the leg's speed a rover went 0.5-0.7 m past a door's corner before it turned and brushed the jamb
    (gen:office seed 1, ArduPilot and PX4 alike)."""
    dn, de = waypoint[0] - position[0], waypoint[1] - position[1]
    bearing = math.atan2(de, dn)
    s = min(speed, APPROACH_GAIN * max(0.0, math.hypot(dn, de) - WAYPOINT_RADIUS) + APPROACH_FLOOR)
    if yaw is None:
        return bearing, s
    err = (bearing - yaw + math.pi) % (2 * math.pi) - math.pi
    if abs(err) > TURN_IN_PLACE:
        return bearing, 0.0
    return bearing, s * math.cos(err)


class FirmwareOperator(ScriptedStation):
    # whether a frozen picture streams a standstill (``_hold_still``) rather than nothing: not where what reaches the
    # vehicle is judged as the native operator's stream (the companion's link watch: the native operator stops
    # streaming then, and the companion's own dead-man stops the rover), nor where another program drives in GUIDED
    # meanwhile (the applet)
    lets_go = True

    def __init__(self, route, resume_route, origin: tuple[float, float], attempts: int = 2,
                 sysid: int = GCS_SYSID, compid: int = GCS_COMPID, target_system: int = 1,
                 rejoin: bool = True) -> None:
        super().__init__(route, resume_route, attempts, rejoin)
        self.mav = apm.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.mav.robust_parsing = True
        self.target = target_system
        self.origin = origin
        self.out: list[bytes] = []
        self.next_heartbeat = 0.0
        self.next_retry = 0.0
        self.mode: int | None = None
        self.armed = False
        self.position: tuple[float, float] | None = None  # world frame, from the last LOCAL_POSITION_NED
        self.speed = 0.0
        self.yaw: float | None = None  # the rover's heading, from the last ATTITUDE
        self.last_position_t: float | None = None
        self.rest_since: float | None = None
        self.sent_target: tuple[float, float] | None = None
        self.next_stick = 0.0
        self.rtl_requested = False

    # ----- what it hears -------------------------------------------------------------------------------------
    def feed(self, data: bytes, t: float) -> None:
        for msg in self.mav.parse_buffer(data) or ():
            if msg.get_srcSystem() != self.target:
                continue
            kind = msg.get_type()
            if kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                self.mode, self.armed = msg.custom_mode, bool(msg.base_mode & apm.MAV_MODE_FLAG_SAFETY_ARMED)
            elif kind == "LOCAL_POSITION_NED":
                self._position_heard(t)
                self.position = (self.origin[0] + msg.x, self.origin[1] + msg.y)
                self.speed = math.hypot(msg.vx, msg.vy)
                self.last_position_t = t
            elif kind == "ATTITUDE":
                self.yaw = msg.yaw
            elif kind == "STATUSTEXT":
                self._text_heard(msg.text, t)

    def _position_heard(self, t: float) -> None:
        """A position report arrives at ``t`` (``last_position_t`` still the one before): for a subclass."""

    def _text_heard(self, text: str, t: float) -> None:
        """A STATUSTEXT from the rover reached the station: for a subclass (this operator reads no texts)."""

    def fresh(self, t: float) -> bool:
        return self.last_position_t is not None and t - self.last_position_t < STALE_TELEMETRY

    # ----- what it sends -------------------------------------------------------------------------------------
    def _send(self, msg) -> None:
        self.out.append(msg.pack(self.mav))

    def _command(self, command: int, *params: float) -> None:
        p = (list(params) + [0.0] * 7)[:7]
        self._send(apm.MAVLink_command_long_message(self.target, 1, command, 0, *p))

    def _set_mode(self, mode: int) -> None:
        self._command(apm.MAV_CMD_DO_SET_MODE, apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)

    def _stick(self, t: float, mask: int, vn: float = 0.0, ve: float = 0.0, yaw: float = 0.0,
               frame: int = apm.MAV_FRAME_LOCAL_NED) -> None:
        """One setpoint of the streamed drive, at most one every STICK_PERIOD."""
        if t < self.next_stick - 1e-9:
            return
        self.next_stick = t + STICK_PERIOD
        self._send(apm.MAVLink_set_position_target_local_ned_message(
            0, self.target, 1, frame, mask, 0, 0, 0, vn, ve, 0, 0, 0, 0, yaw, 0))

    def _steer(self, t: float, waypoint: tuple[float, float], speed: float) -> None:
        """Drive toward ``waypoint`` at the leg's ``speed`` as the native rover would (``drive_setpoint``): a NED
        velocity, or a heading alone to turn on the spot."""
        if self.position is None:
            return
        bearing, s = drive_setpoint(self.position, self.yaw, waypoint, speed)
        if s > 0.0:
            self._stick(t, VELOCITY_ONLY, s * math.cos(bearing), s * math.sin(bearing))
        else:
            self._stick(t, HEADING_ONLY, yaw=bearing)

    def _hold_still(self, t: float) -> None:
        """A zero stick, streamed as the native station streams it (``GroundStation.stop``): when the route is
        driven, and when the picture has frozen: the hand comes off the stick and the joystick streams it at rest
        whatever the station hears, as the native station's does, which stops the rover as soon as any of it gets
        through a fading link (GUIDED alone would keep driving the last velocity for 3 s)."""
        self._stick(t, STOPPED, frame=apm.MAV_FRAME_BODY_NED)

    def request_rtl(self, t: float) -> None:
        """A scripted RTL (the scenario's ``rtl`` event): the operator switches the firmware to RTL."""
        self.rtl_requested = True
        self._say(t, "rtl requested")

    def tick(self, t: float) -> list[bytes]:
        self.out = []
        if t >= self.next_heartbeat:
            self.next_heartbeat = t + 1.0
            self._send(apm.MAVLink_heartbeat_message(apm.MAV_TYPE_GCS, apm.MAV_AUTOPILOT_INVALID, 0, 0,
                                                     apm.MAV_STATE_ACTIVE, 3))
        if self.rtl_requested:
            self.rtl_requested = False
            self._set_mode(RTL)
            self.phase = "rtl"
        self._step(t)
        return self.out

    def _step(self, t: float) -> None:
        retry = t >= self.next_retry
        if self.phase in ("connect", "guided", "arming"):
            self._set_up(t, retry)
        elif not self.fresh(t):
            self._lost_on_the_way()
            if self.lets_go and self.mode == GUIDED and self.phase in ("driving", "resuming"):
                self._hold_still(t)  # the picture froze: it lets go of the stick (see ``_hold_still``)
        elif self.mode in RETURN_MODES:
            self._after_return(t, retry)
        else:
            self.rest_since = None
            if self.mode != GUIDED:
                return
            leg = self.resume if self.phase == "resuming" else self.leg
            if self.phase == "driving" and leg.done:
                self._hold_still(t)
                return
            self._drive(leg, t)

    def _set_up(self, t: float, retry: bool) -> None:
        """Ask for the position and attitude streams, switch to GUIDED, arm: one step at a time, retried."""
        phase = self.phase
        if phase == "connect":
            if self.mode is not None and retry:
                self.next_retry = t + RETRY_S
                self._command(apm.MAV_CMD_SET_MESSAGE_INTERVAL, apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                              LOCAL_POSITION_INTERVAL_US)
                self._command(apm.MAV_CMD_SET_MESSAGE_INTERVAL, apm.MAVLINK_MSG_ID_ATTITUDE, ATTITUDE_INTERVAL_US)
                self.phase = "guided"
        elif phase == "guided":
            if self.mode == GUIDED:
                self.phase = "arming"
            elif retry:
                self.next_retry = t + RETRY_S
                self._set_mode(GUIDED)
        elif self.armed:
            self.phase = "driving"
            self._say(t, "armed, driving")
        elif retry:
            self.next_retry = t + RETRY_S
            self._command(apm.MAV_CMD_COMPONENT_ARM_DISARM, 1)

    def _after_return(self, t: float, retry: bool) -> None:
        """A return mode (the failsafe's, or the one the operator asked for): once the rover holds or has stood
        still for REST_S, the operator counts the loss and takes it back in GUIDED, unless it asked for that RTL."""
        phase = self.phase
        self._lost_on_the_way()
        if self.speed < REST_SPEED:
            self.rest_since = t if self.rest_since is None else self.rest_since
        else:
            self.rest_since = None
        if not (self.mode == HOLD or (self.rest_since is not None and t - self.rest_since >= REST_S)):
            return
        if phase == "rtl":
            return  # the operator asked for this return: it leaves the rover where RTL took it
        self._count_loss()
        if retry:
            self.next_retry = t + RETRY_S
            self._set_mode(GUIDED)
            self.sent_target = None
            self._say(t, "taking control back")
            if phase == "driving":
                self.phase = "resuming"
            self._rejoin()

    def _count_loss(self) -> None:
        """The rover came back without the link: the waypoint it was driving toward counts one loss, once (it is
        driven toward again only when the operator drives again)."""
        super()._count_loss()
        self.heading_to = None

    def _rejoin(self) -> None:
        """After a return, the resume route picked up where the native operator picks it up (``Leg.join``)."""
        self._pick_up_way_home(self.position)

    def _drive(self, leg: Leg, t: float) -> None:
        while not leg.done:
            x, y, speed = leg.points[leg.index]
            place = (x, y)
            if self._given_up(place):  # lost the link on the way there often enough
                leg.index += 1
                continue
            if self.position is not None and math.dist(place, self.position) < WAYPOINT_RADIUS:
                leg.index += 1
                continue
            break
        if leg.done:
            self.heading_to = None
            self._hold_still(t)
            return
        x, y, speed = leg.points[leg.index]
        self.heading_to = (x, y)
        self._steer(t, (x, y), speed)
