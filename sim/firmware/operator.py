"""The scripted operator of a firmware run: a person at a ground station flying an ArduPilot rover in GUIDED.

It is the firmware's counterpart of ``sim.operator.Operator`` and knows only what reached it over the radio. It
sends a GCS heartbeat every second (what keeps the firmware's GCS failsafe quiet, and nothing else does), asks for
the local position at 5 Hz, switches to GUIDED and arms (retrying each second until the heartbeat shows it), then
drives the scenario route as a GUIDED user does: a speed (DO_CHANGE_SPEED) and position targets
(SET_POSITION_TARGET_LOCAL_NED, position only; the firmware steers) that keep the rover on the way to each waypoint
(``_aim``), the next waypoint once its telemetry shows the rover within ``WAYPOINT_RADIUS``. Position targets do not
time out in Rover: a target sent before the link died is still driven to until the failsafe changes the mode, which
is what the real firmware does to a real operator.

When its picture freezes it keeps its heartbeat going and stops sending targets. When it hears the rover again and
sees the firmware's failsafe has done its work (the rover in HOLD, or at rest in RTL/SMART_RTL for
``REST_S``), it takes control again (GUIDED) and drives the resume route; like the native operator it gives up a
waypoint after ``attempts`` losses on the way to it.

Positions: the scenario route is in the world frame (x north, y east); the firmware's LOCAL_POSITION_NED is
relative to its EKF origin, where the rover stood when it got its first fix, i.e. the scenario's start.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from sim.operator import Leg

GCS_SYSID, GCS_COMPID = 255, 190
WAYPOINT_RADIUS = 1.5  # m
STALE_TELEMETRY = 1.5  # s: no position report for this long and the picture has frozen
RETRY_S = 1.0
REST_S = 2.0  # s at rest in a return mode before the operator takes over again
REST_SPEED = 0.1  # m/s
GUIDED, HOLD, RTL, SMART_RTL = 15, 4, 11, 12
RETURN_MODES = frozenset((HOLD, RTL, SMART_RTL))
POSITION_ONLY = 0x0DF8  # SET_POSITION_TARGET type mask: x, y, z used; velocity, acceleration, yaw, yaw rate not
LOCAL_POSITION_INTERVAL_US = 200_000
CARROT_S = 4.0  # s: how far ahead on the way the operator puts its target, in travel time at the leg's speed
CARROT_MIN_M = 2.0  # m: never nearer than this (beyond the firmware's WP_RADIUS of 1 m, where it would stop)
CARROT_STEP_M = 1.0  # m: the target is moved on once the rover's progress would move it this far


class FirmwareOperator:
    def __init__(self, route, resume_route, origin: tuple[float, float], attempts: int = 2,
                 sysid: int = GCS_SYSID, compid: int = GCS_COMPID, target_system: int = 1) -> None:
        self.mav = apm.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.mav.robust_parsing = True
        self.target = target_system
        self.origin = origin
        self.leg = Leg(tuple(route))
        self.resume = Leg(tuple(resume_route))
        self.attempts = attempts
        self.phase = "connect"
        self.out: list[bytes] = []
        self.next_heartbeat = 0.0
        self.next_retry = 0.0
        self.mode: int | None = None
        self.armed = False
        self.position: tuple[float, float] | None = None  # world frame, from the last LOCAL_POSITION_NED
        self.speed = 0.0
        self.last_position_t: float | None = None
        self.rest_since: float | None = None
        self.sent_target: tuple[float, float] | None = None
        self.heading_to: tuple[float, float] | None = None
        self.cut_off: tuple[float, float] | None = None
        self.losses: dict[tuple[float, float], int] = {}
        self.rtl_requested = False
        self.log: list[tuple[float, str]] = []

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

    def _goto(self, x: float, y: float, speed: float) -> None:
        self._command(apm.MAV_CMD_DO_CHANGE_SPEED, 1, speed, -1)
        n, e = x - self.origin[0], y - self.origin[1]
        self._send(apm.MAVLink_set_position_target_local_ned_message(
            0, self.target, 1, apm.MAV_FRAME_LOCAL_NED, POSITION_ONLY, n, e, 0, 0, 0, 0, 0, 0, 0, 0, 0))
        self.sent_target = (x, y)

    def request_rtl(self, t: float) -> None:
        """A scripted RTL (the scenario's ``rtl`` event): the operator switches the firmware to RTL."""
        self.rtl_requested = True
        self.log.append((t, "rtl requested"))

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
        phase = self.phase
        retry = t >= self.next_retry
        if phase == "connect":
            if self.mode is not None and retry:
                self.next_retry = t + RETRY_S
                self._command(apm.MAV_CMD_SET_MESSAGE_INTERVAL, apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                              LOCAL_POSITION_INTERVAL_US)
                self.phase = "guided"
            return
        if phase == "guided":
            if self.mode == GUIDED:
                self.phase = "arming"
            elif retry:
                self.next_retry = t + RETRY_S
                self._set_mode(GUIDED)
            return
        if phase == "arming":
            if self.armed:
                self.phase = "driving"
                self.log.append((t, "armed, driving"))
            elif retry:
                self.next_retry = t + RETRY_S
                self._command(apm.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            return
        fresh = self.fresh(t)
        if not fresh:
            self.cut_off = self.heading_to or self.cut_off
            self.sent_target = None  # resend once the picture is back
            return
        if self.mode in RETURN_MODES:
            self.cut_off = self.heading_to or self.cut_off
            if self.speed < REST_SPEED:
                self.rest_since = t if self.rest_since is None else self.rest_since
            else:
                self.rest_since = None
            if self.mode == HOLD or (self.rest_since is not None and t - self.rest_since >= REST_S):
                if phase == "rtl":
                    return  # the operator asked for this return: it leaves the rover where RTL took it
                if self.cut_off is not None:
                    self.losses[self.cut_off] = self.losses.get(self.cut_off, 0) + 1
                    self.cut_off = None
                if retry:
                    self.next_retry = t + RETRY_S
                    self._set_mode(GUIDED)
                    self.sent_target = None
                    self.log.append((t, "taking control back"))
                    if phase == "driving":
                        self.phase = "resuming"
            return
        self.rest_since = None
        if self.mode != GUIDED:
            return
        leg = self.resume if self.phase == "resuming" else self.leg
        if self.phase == "driving" and leg.done:
            return
        self._drive(leg, t)

    def _drive(self, leg: Leg, t: float) -> None:
        while not leg.done:
            x, y, speed = leg.points[leg.index]
            place = (x, y)
            if self.losses.get(place, 0) >= self.attempts:  # lost the link on the way there often enough
                leg.index += 1
                continue
            if self.position is not None and math.dist(place, self.position) < WAYPOINT_RADIUS:
                leg.index += 1
                continue
            break
        if leg.done:
            self.heading_to = None
            return
        x, y, speed = leg.points[leg.index]
        self.heading_to = (x, y)
        aim = self._aim(leg)
        sent = self.sent_target
        moved = sent is None or (aim != sent and (aim == (x, y) or math.dist(aim, sent) >= CARROT_STEP_M))
        if moved or t >= self.next_retry:
            self.next_retry = t + 2 * RETRY_S  # a target is idempotent: resent now and then against a lost packet
            self._goto(*aim, speed)

    def _aim(self, leg: Leg) -> tuple[float, float]:
        """Where to send the rover on its way to the leg's current waypoint: a point ``CARROT_S`` of travel at the
        leg's speed (at least ``CARROT_MIN_M``) ahead of it on the stretch from the waypoint before, or the waypoint
        itself when that is nearer or there is none.

        GUIDED steers straight at a position target, and a person steering a rover down a tunnel keeps it on the
        way, not on the line from wherever it stands to a waypoint 45 m off: from a rest place beside the tunnel's
        wall (where a return leaves it, 1.4 m off the middle at the bend) that line runs along the wall and the
        rover scrapes it all the way. Nearer at a slow leg: a door is driven slowly, and a rover left 1.4 m off the
        line beside it (where a return came to rest) steered at a target 6 m ahead cut across the door's jamb
        (building, seed 3, measured); a target 2 m ahead brings it onto the line before the door."""
        x, y = leg.points[leg.index][:2]
        if leg.index == 0 or self.position is None:
            return x, y
        ax, ay = leg.points[leg.index - 1][:2]
        dx, dy = x - ax, y - ay
        length = math.hypot(dx, dy)
        if length < 1e-9:
            return x, y
        ux, uy = dx / length, dy / length
        speed = leg.points[leg.index][2]
        along = max(0.0, (self.position[0] - ax) * ux + (self.position[1] - ay) * uy) + max(CARROT_MIN_M,
                                                                                           CARROT_S * speed)
        if along >= length:
            return x, y
        return ax + along * ux, ay + along * uy
