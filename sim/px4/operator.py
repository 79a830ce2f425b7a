"""The scripted operator of a PX4 run: a person at a ground station flying a PX4 rover in Offboard.

It is the PX4 counterpart of ``sim.firmware.operator.FirmwareOperator`` (whose route following it shares: the
waypoints, the native operator's steering toward each, the resume route picked up after a return, giving a waypoint
up after ``attempts`` losses) and knows only what reached it over the radio. Why Offboard with velocity setpoints:
- PX4 rover drives a ground station's route in three ways: a mission (AUTO_MISSION, uploaded whole, which is not how
  the scenario's operator drives: it decides leg by leg from what it sees), Manual/Position with MANUAL_CONTROL
  sticks (COM_RC_IN_MODE 1 in SITL; the runs preset 4, no stick input, so nothing waits for or fails over an RC
  link nobody simulates), or Offboard. Offboard is the GUIDED of PX4, what ArduPilot's operator flies.
- Velocity setpoints (SET_POSITION_TARGET_LOCAL_NED, velocity only), steered as the native operator steers its rover
  (``sim.firmware.operator.drive_setpoint``: straight at each waypoint at the leg's speed, slowing before the corner,
  turning on the spot where the heading is far off), so that a comparison with the native rover is one of returns,
  not of drivers. PX4's differential rover reads a velocity target as a speed and a bearing, turns to the bearing (on
  the spot when more than RD_TRANS_DRV_TRN off) and drives along it (``vehicle.companion.px4``). The position
  targets this operator used to send, a carrot on the line between waypoints, cut door jambs on that line: a
  generated world puts each waypoint WAYPOINT_RADIUS beyond its corner for the native steering. A velocity target is
  kept while the stream is silent (until COM_OF_LOSS_T, which the runs set long so that the data-link failsafe is
  what they measure): when its picture freezes, the operator lets go of its stick (a target of STOP_SPEED along the
  last bearing, streamed on), and a rover whose uplink died drives its last velocity until PX4's failsafe, which is
  PX4's own behaviour. Position targets stay for standing still before Offboard and after a failsafe.
- The stream: Offboard needs setpoints before the switch and leaves Offboard when they stop for COM_OF_LOSS_T, so
  the operator streams its current target at ``STREAM_HZ`` from before arming to the end, as an offboard program
  does, whatever its picture; a frozen picture only makes it a standstill.

It sends a GCS heartbeat every second (PX4 counts only a GCS-type HEARTBEAT as its data link), learns PX4's system
id from its HEARTBEAT (instance + 1), asks for LOCAL_POSITION_NED and ATTITUDE at 5 Hz, streams a target where the
rover stands for ``STREAM_LEAD_S``, arms, switches to Offboard (each retried every second until the heartbeat shows
it), then drives the route. When the link comes back and PX4's failsafe has done its work (the rover in Hold, or at
rest in Return for ``REST_S``) it takes control again (Offboard; arming again first if PX4 disarmed) and drives the
resume route, as the ArduPilot operator does.

Positions: the scenario route is in the true frame (x north, y east); PX4's LOCAL_POSITION_NED is relative to its
EKF2 origin, which the operator places from HOME_POSITION (its global position, converted around the scenario's GPS
origin, minus its local one), as a ground station with a map would.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mav

from link.mission import Origin
from sim.firmware.operator import (
    ATTITUDE_INTERVAL_US,
    GCS_COMPID,
    GCS_SYSID,
    LOCAL_POSITION_INTERVAL_US,
    POSITION_ONLY,
    REST_S,
    REST_SPEED,
    RETRY_S,
    VELOCITY_ONLY,
    FirmwareOperator,
    drive_setpoint,
)
from sim.px4.hil import to_local
from sim.px4.lockstep import HOLD, MAIN_OFFBOARD, OFFBOARD, RETURN

STOP_SPEED = 1e-3  # m/s: a velocity target that means "stand still facing this way" (a zero vector is bearing north)
STREAM_HZ = 10.0  # setpoints a second: PX4 wants more than 2 Hz for Offboard
STREAM_LEAD_S = 1.0  # s of setpoints before the switch to Offboard, as PX4 requires a live stream for it
RETURN_MODES = frozenset((HOLD, RETURN))  # where PX4's data-link failsafe puts the rover


class PX4Operator(FirmwareOperator):
    """The operator's station flying PX4 in Offboard (see the module docstring). ``geo``: the scenario's GPS
    origin, where the map's (0, 0) lies on the globe."""

    def __init__(self, route, resume_route, geo: Origin, attempts: int = 2, sysid: int = GCS_SYSID,
                 compid: int = GCS_COMPID, rejoin: bool = True) -> None:
        super().__init__(route, resume_route, (0.0, 0.0), attempts, sysid, compid, target_system=0, rejoin=rejoin)
        self.mav = mav.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.mav.robust_parsing = True
        self.geo = geo
        self.frame: tuple[float, float] | None = None  # PX4's local (0, 0) in the true frame, from HOME_POSITION
        # the target streamed: ("position", x, y) in the true frame or ("velocity", bearing, speed)
        self.setpoint: tuple[str, float, float] | None = None
        self.next_setpoint = 0.0
        self.stream_since: float | None = None
        self.after_arming = "driving"  # the phase arming leads to (driving, or resuming after a re-arm)

    # ----- what it hears -------------------------------------------------------------------------------------
    def feed(self, data: bytes, t: float) -> None:
        for msg in self.mav.parse_buffer(data) or ():
            kind = msg.get_type()
            if kind == "HEARTBEAT":
                if msg.get_srcComponent() == 1 and msg.autopilot == mav.MAV_AUTOPILOT_PX4:
                    self.target = msg.get_srcSystem()
                    self.mode, self.armed = msg.custom_mode, bool(msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
                continue
            if msg.get_srcSystem() != self.target:
                continue
            if kind == "HOME_POSITION":
                hx, hy = to_local(self.geo, msg.latitude / 1e7, msg.longitude / 1e7)
                self.frame = (hx - msg.x, hy - msg.y)
            elif kind == "ATTITUDE":
                self.yaw = msg.yaw
            elif kind == "LOCAL_POSITION_NED" and self.frame is not None:
                self.position = (self.frame[0] + msg.x, self.frame[1] + msg.y)
                self.speed = math.hypot(msg.vx, msg.vy)
                self.last_position_t = t

    # ----- what it sends -------------------------------------------------------------------------------------
    def _command(self, command: int, *params: float) -> None:
        p = (list(params) + [0.0] * 7)[:7]
        self._send(mav.MAVLink_command_long_message(self.target, 1, command, 0, *p))

    def _set_mode(self, mode: int) -> None:
        """PX4's custom mode by its main and sub mode numbers (DO_SET_MODE takes them as params 2 and 3)."""
        self._command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, (mode >> 16) & 0xFF,
                      (mode >> 24) & 0xFF)

    def _goto(self, x: float, y: float, speed: float) -> None:
        """A position target where PX4 drives and stops, streamed from now on (PX4's Offboard position target has
        no speed)."""
        self.setpoint = ("position", x, y)

    def _steer(self, t: float, waypoint: tuple[float, float], speed: float) -> None:
        """Drive toward ``waypoint`` at the leg's ``speed`` as the native rover would (``drive_setpoint``): a velocity
        target, streamed from now on; one of STOP_SPEED along the bearing turns the rover to it on the spot."""
        if self.position is None:
            return
        bearing, s = drive_setpoint(self.position, self.yaw, waypoint, speed)
        self.setpoint = ("velocity", bearing, s)

    def _hold_still(self, t: float) -> None:
        """Stand still facing the way it faces (the route is driven, or the picture froze: the native operator stops
        pushing its stick): a velocity target of STOP_SPEED along the last bearing streamed, or a position target
        where it stands when it was not driving by velocity."""
        sp = self.setpoint
        if sp is not None and sp[0] == "velocity":
            self.setpoint = ("velocity", sp[1], 0.0)
        elif sp is None and self.position is not None:
            self._goto(*self.position, 0.0)

    def _stream(self, t: float) -> None:
        if self.setpoint is None or self.frame is None or t < self.next_setpoint - 1e-9:
            return
        self.next_setpoint = t + 1.0 / STREAM_HZ
        kind, a, b = self.setpoint
        if kind == "position":
            n, e = a - self.frame[0], b - self.frame[1]
            self._send(mav.MAVLink_set_position_target_local_ned_message(
                int(t * 1000), self.target, 1, mav.MAV_FRAME_LOCAL_NED, POSITION_ONLY, n, e, 0, 0, 0, 0, 0, 0, 0,
                0, 0))
        else:
            v = max(b, STOP_SPEED)
            self._send(mav.MAVLink_set_position_target_local_ned_message(
                int(t * 1000), self.target, 1, mav.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY, 0, 0, 0, v * math.cos(a),
                v * math.sin(a), 0, 0, 0, 0, 0, 0))

    def tick(self, t: float) -> list[bytes]:
        self.out = []
        if t >= self.next_heartbeat:
            self.next_heartbeat = t + 1.0
            self._send(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0,
                                                     mav.MAV_STATE_ACTIVE, 3))
        if self.rtl_requested and self.target:
            self.rtl_requested = False
            self._set_mode(RETURN)
            self.phase = "rtl"
        self._step(t)
        self._stream(t)
        return self.out

    def _step(self, t: float) -> None:
        phase = self.phase
        retry = t >= self.next_retry
        if phase == "connect":
            if self.target and retry:
                self.next_retry = t + RETRY_S
                self._command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                              LOCAL_POSITION_INTERVAL_US)
                self._command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, ATTITUDE_INTERVAL_US)
            if self.fresh(t):
                self._hold_here(t)
                self.phase = "arming"
            return
        if phase == "arming":
            self._arm(t, retry)
            return
        if phase == "offboard":
            if self.mode == OFFBOARD:
                self.phase = self.after_arming
                self._say(t, "offboard, driving")
            elif retry:
                self.next_retry = t + RETRY_S
                self._set_mode(OFFBOARD)
            return
        fresh = self.fresh(t)
        if not fresh:
            self._lost_on_the_way()
            self._hold_still(t)  # the picture froze: it stops pushing (the stream goes on, as Offboard needs)
            return
        if self.mode in RETURN_MODES or not self.armed:
            self._after_failsafe(t, retry)
            return
        self.rest_since = None
        if (self.mode >> 16) & 0xFF != MAIN_OFFBOARD:
            return
        leg = self.resume if self.phase == "resuming" else self.leg
        if self.phase == "driving" and leg.done:
            return
        self._drive(leg, t)

    def _hold_here(self, t: float) -> None:
        """Stream a target where the rover stands: PX4 wants a live stream before Offboard, and this one keeps the
        rover still when it comes."""
        self._goto(*self.position, 0.0)
        self.heading_to = None
        self.stream_since = t

    def _arm(self, t: float, retry: bool) -> None:
        if self.stream_since is None or t - self.stream_since < STREAM_LEAD_S - 1e-9:
            return
        if self.armed:
            self.phase = "offboard"
            self.next_retry = t
            self._say(t, "armed")
        elif retry:
            self.next_retry = t + RETRY_S
            self._command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)

    def _after_failsafe(self, t: float, retry: bool) -> None:
        """PX4's failsafe holds the rover (or drove it back and it rests, or disarmed it): note the loss against
        the waypoint it was heading to, and once it is at rest take control again."""
        self._lost_on_the_way()
        if self.speed < REST_SPEED:
            self.rest_since = t if self.rest_since is None else self.rest_since
        else:
            self.rest_since = None
        if not (self.mode == HOLD or not self.armed
                or (self.rest_since is not None and t - self.rest_since >= REST_S)):
            return
        if self.phase == "rtl":
            return  # the operator asked for this return: it leaves the rover where Return took it
        self._count_loss()
        self._say(t, "taking control back")
        self.after_arming = "resuming"
        if self.rejoin and self.position is not None:
            self.resume.join(*self.position)  # picked up as the native operator picks it up (``Leg.join``)
        self._hold_here(t)
        self.stream_since = t - STREAM_LEAD_S  # the stream never stopped on this side: switch at once
        self.next_retry = t
        self.phase = "offboard" if self.armed else "arming"
