"""An ArduPilot Rover or a PX4 rover as the robot: a ``RobotDriver`` over MAVLink instead of wheels and sensors
(docs/architecture.md §11, §11.2). This module commands; its parts each hold one concept:

- ``vehicle.companion.rules``: which autopilot it is (its first HEARTBEAT: ``autopilot`` 3 ArduPilot, 12 PX4) and
  that autopilot's rules object (mode numbers, how a mode is asked for, streams, parameters, steering); the driver
  asks the rules object, never which autopilot it drives. PX4's numbers and encodings: ``vehicle.companion.px4``.
- ``vehicle.companion.observed``: what the autopilot says (its own filtered estimate, mode, parameters), and the
  vehicle's readings made of it. The rover's range data (DISTANCE_SENSOR, asked for at 10 Hz beside the estimate,
  and OBSTACLE_DISTANCE; from the autopilot or from any other component of its system, such as a lidar driver) is
  the vehicle's range sensor (``vehicle.companion.ranges``): the return keeps its body off what it sees, as the
  native rover's does.
- ``vehicle.companion.targets``: the vehicle's speed and yaw rate as the autopilot takes them.
- ``vehicle.companion.mode_request``: a mode asked for, followed until the autopilot shows it.
- ``vehicle.companion.upkeep``: the backstop heartbeat and the stream requests, sent whatever a return does.

What follows is ArduPilot's story; PX4's is in ``vehicle.companion.px4``. Commands reach the autopilot only while a
return holds the lease (``engage``): the companion switches it to GUIDED and streams SET_POSITION_TARGET_LOCAL_NED
velocity and turn-rate targets at 10 Hz. Rover stops a velocity target 3 s after the last one, which makes the stream
a dead-man: a companion that dies mid-return leaves a rover that stops. On ``release`` it brakes and then switches
to HOLD, unless someone else already chose a mode: Rover's HOLD sets the throttle to zero and lets the rover roll
(beside the firmware's own physics, 3.2 m from 1.9 m/s), so the companion first streams zero-velocity targets, which
the speed controller brakes to at its deceleration limit, until the rover stands (DESIGN §6.2; PX4 alike, zero
Offboard setpoints before Hold, which stops 1.5-2 cm shorter than Hold at once: ``PX4Rules.brakes``). While
engaged, a mode change it did not ask for (the pilot's RC switch, the autopilot's own failsafe, a ground station) is
reported by ``tick``: the return ends rather than fight the pilot.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion.mode_request import ModeRequest, Step
from vehicle.companion.observed import EstimateFeed, Observed, believe
from vehicle.companion.ranges import KINDS as RANGE_KINDS
from vehicle.companion.ranges import RangeSensors
from vehicle.companion.rules import ArduPilotRules, Rules, is_autopilot_heartbeat, rules_for
from vehicle.companion.targets import TARGET_PERIOD, Steering
from vehicle.companion.upkeep import COMPANION_COMPID, Upkeep
from vehicle.io import Readings

SLOWING = 0.3  # m/s: a command this much slower than the last target's is sent at once
BRAKE_MAX_S = 5.0  # s: zero targets at most this long before HOLD anyway (a rover on a slope, a noisy estimate)


class AutopilotDriver:
    """The ``RobotDriver`` over MAVLink (see the module docstring). Frames for the autopilot go to ``send``."""

    mav_type = apm.MAV_TYPE_ONBOARD_CONTROLLER  # the companion's own HEARTBEAT (docs/architecture.md §11)

    def __init__(self, send: Callable[[bytes], None], pivots: bool = False) -> None:
        """``pivots``: the rover turns on the spot (skid steering); otherwise a turn in place creeps."""
        self.send = send
        self.pivots = pivots
        self.rules: Rules = ArduPilotRules  # until the autopilot's HEARTBEAT says
        self.seen = Observed()
        self.feed = EstimateFeed()
        self.enc: apm.MAVLink | None = None  # as (the autopilot's sysid, 191), once that sysid is known
        self.upkeep = Upkeep()
        self.steering: Steering = self.rules.steering(pivots)
        self.request = ModeRequest()  # the mode asked for and not yet seen
        self.command_out = (0.0, 0.0)
        self.direction = 1.0  # the sign of the last speed driven: a creeping turn keeps going that way
        self.engaged = False
        self.confirmed = False  # the drive mode seen (or acknowledged) since engaging
        self.mode_at_engage: int | None = None
        self.next_target = -math.inf
        self.switch_at: float | None = None  # when to ask for the drive mode, once the stream runs (PX4)
        self.sent_command = 0.0  # the speed command the last target carried (before the steering's governor)
        self.braking_since: float | None = None  # released to HOLD, streaming zero targets until the rover stands
        self.ranges = RangeSensors()  # the rover's range data, heard from any component of the autopilot's system

    # ----- what the autopilot says ---------------------------------------------------------------------------
    def observe(self, m, t: float) -> None:
        """One message from the autopilot side (any component; only the autopilot's own are believed, the range
        data of any component of its system)."""
        s = self.seen
        kind = m.get_type()
        if kind == "BAD_DATA":
            return
        if s.sysid is None and is_autopilot_heartbeat(m):
            self._meet(m)
        if kind in RANGE_KINDS and s.sysid is not None and m.get_srcSystem() == s.sysid:
            # the autopilot's rangefinders, or a lidar driver's sectors: another component of the vehicle counts
            self.ranges.heard(m, t, s.yaw())
        if not believe(s, m, t, self.rules):
            return
        if kind == "COMMAND_ACK" and m.command == apm.MAV_CMD_DO_SET_MODE and self._for_me(m):
            self.request.answered(m, t, s, self.rules)

    def _meet(self, m) -> None:
        """The autopilot's first HEARTBEAT: who it is, and so its rules and the companion's encoder."""
        s = self.seen
        s.sysid, s.compid = m.get_srcSystem(), m.get_srcComponent()
        self.enc = apm.MAVLink(None, s.sysid, COMPANION_COMPID)
        self.rules = rules_for(m.autopilot)
        self.steering = self.rules.steering(self.pivots)

    def _for_me(self, m) -> bool:
        return m.target_system in (0, self.seen.sysid) and m.target_component in (0, COMPANION_COMPID)

    @property
    def armed(self) -> bool:
        return self.seen.armed

    @property
    def keepalives(self) -> int:
        """Backstop heartbeats sent, for the record."""
        return self.upkeep.keepalives

    def lost(self, t: float) -> bool:
        return self.seen.lost(t)

    def ready(self) -> bool:
        """The autopilot has said who it is and where it is: the vehicle can boot on its estimate."""
        return self.seen.ready()

    def pose(self) -> tuple[float, float, float]:
        return self.seen.pose()

    def mode_name(self, mode: int | None) -> str:
        """``mode`` as the autopilot driven names it."""
        return self.rules.mode_name(mode)

    # ----- RobotDriver -----------------------------------------------------------------------------------------
    def read(self, t: float, dt: float) -> Readings:
        """This tick's readings (``EstimateFeed.read``), with the range data heard since the last tick as a scan."""
        return self.feed.read(self.seen, t, self.ranges.scan(t))

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
        self.engaged, self.request.refused = True, None
        self.braking_since = None
        self.mode_at_engage = self.seen.mode
        self.switch_at = None
        self.steering.begin()
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
        self.switch_at = None
        self.request.drop()
        if hold and self.seen.mode == self.rules.drive:
            if self.rules.brakes:
                self.braking_since, self.next_target = t, t
                self._brake(t)
            else:
                self._ask(self.rules.hold, t)

    def speed_along(self, t: float) -> tuple[float, float] | None:
        """The rover's speed along its heading and its rate of change (``Observed.speed_along``)."""
        return self.seen.speed_along(t)

    def standing(self, t: float) -> bool:
        """The autopilot's fresh estimate says the rover stands (``Observed.standing``)."""
        return self.seen.standing(t)

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
        if self.seen.standing(t) or t - since >= BRAKE_MAX_S:
            self.braking_since = None
            self._ask(self.rules.hold, t)
            return
        if t >= self.next_target:
            self.next_target = t + TARGET_PERIOD
            self._zero_target(t)

    def stop_braking(self) -> None:
        """The owner drives the autopilot again: its targets, not the brake's."""
        self.braking_since = None

    def _ask(self, mode: int, t: float) -> None:
        self.request.ask(mode)
        self._request_mode(t)

    def _request_mode(self, t: float) -> None:
        wanted = self.request.wanted
        if self.enc is None or wanted is None:
            return
        self.request.sent(t)
        self.send_message(self.rules.set_mode(self.enc, self.seen.sysid, self.seen.compid, wanted))

    def tick(self, t: float, healthy: bool) -> str | None:
        """Send what is due (keepalive, stream requests, mode requests, targets) and say why the return lost the
        autopilot, if it did this tick (None: it did not)."""
        if self.enc is None or self.lost(t):
            return None
        self._upkeep(t, healthy)
        why = self._follow_request(t)
        if why is not None:
            return why
        if not self.engaged:
            self._brake(t)
            return None
        why = self._taken_from_return()
        if why is not None:
            return why
        self._drive(t)
        return None

    def _upkeep(self, t: float, healthy: bool) -> None:
        """The backstop heartbeat and the stream requests due (``vehicle.companion.upkeep``)."""
        u = self.upkeep
        beat = u.keepalive(t, healthy, self.seen, self.rules)
        if beat is not None:
            self.send_message(beat, u.keepalive_enc)
        assert self.enc is not None
        for msg in u.requests(t, self.enc, self.seen, self.rules):
            self.send_message(msg)

    def _follow_request(self, t: float) -> str | None:
        """The pending mode request: done, sent again, or given up (then, while engaged, why the return ends)."""
        req = self.request
        step = req.step(t, self.seen, self.rules)
        if step is Step.RESEND:
            self._request_mode(t)
        elif step is Step.GAVE_UP:
            why = req.refused or f"the autopilot did not switch to {self.mode_name(req.wanted)}"
            req.drop()
            if self.engaged:
                return why
        return None

    def _taken_from_return(self) -> str | None:
        """Why the engaged return no longer has the autopilot (disarmed, or a mode nobody on the companion asked
        for), or None; the drive mode seen confirms the engagement."""
        s, r = self.seen, self.rules
        if not s.armed:
            return "the autopilot was disarmed, not by the companion: return ended"
        if s.mode == r.drive and (r.lead is None or (self.switch_at is None and self.request.wanted is None)):
            self.confirmed = True
        elif s.mode is not None and (self.confirmed or not self._unconfirmed_ok(s.mode)):
            return f"the autopilot switched to {self.mode_name(s.mode)}, not by the companion: return ended"
        return None

    def _drive(self, t: float) -> None:
        """The return's targets (every TARGET_PERIOD, or at once when told to slow down) and, PX4, Offboard asked
        for once the stream runs."""
        r = self.rules
        streaming = self.seen.mode == r.drive or r.lead is not None  # PX4: the stream runs before, and into, Offboard
        # a command to slow down (the approach speed, heard again) goes out at once, not up to a period later
        slowing = abs(self.command_out[0]) < abs(self.sent_command) - SLOWING
        if streaming and (t >= self.next_target or slowing):
            self.next_target = t + TARGET_PERIOD
            self._target(t)
        if self.switch_at is not None and t >= self.switch_at:
            self.switch_at = None
            self._ask(r.drive, t)

    def _unconfirmed_ok(self, mode: int) -> bool:
        """Whether ``mode``, seen before the autopilot confirmed the companion's drive mode, is no one's choice:
        the mode the return found (ArduPilot), or also PX4's Offboard and the Hold its Offboard loss of the owner's
        dead stream leads to (PX4)."""
        if mode == self.mode_at_engage:
            return True
        return self.rules.lead is not None and mode in (self.rules.drive, self.rules.hold)

    def _target(self, t: float) -> None:
        """One target for the vehicle's command, as the autopilot driven takes it (``vehicle.companion.targets``)."""
        assert self.enc is not None
        speed, yaw_rate = self.command_out
        self.sent_command = speed
        self.send_message(self.steering.target(self.enc, self.seen, t, speed, yaw_rate, self.direction))

    def resume(self, t: float) -> None:
        """Back to the drive mode the owner was driving in (PX4: Offboard, after a Hold that nobody on the ground
        asked for; ``vehicle.companion.drive_watch``)."""
        self._ask(self.rules.drive, t)

    def stop(self, t: float = 0.0) -> bool:
        """A zero-velocity target: the rover stops where it is and stays in GUIDED, so a return that follows
        drives at once, with no mode switch (the companion's dead-man over the owner's drive,
        ``vehicle.companion.drive_watch``). False: nothing sent (the autopilot is not in GUIDED, or not known yet).

        PX4: Hold (AUTO_LOITER) instead, asked for at ``t``. Offboard needs a stream, so standing in Offboard would
        mean the companion streaming stops in the owner's name, racing the owner's own setpoints when it speaks
        again and keeping an Offboard alive that PX4 would otherwise end itself after COM_OF_LOSS_T (for the
        same Hold: COM_OBL_RC_ACT). The return that follows streams first and switches to Offboard, a fifth of a
        second."""
        if self.enc is None or self.seen.mode != self.rules.drive:
            return False
        if self.rules.stop_holds:
            if self.request.wanted != self.rules.hold:
                self._ask(self.rules.hold, t)
            return True
        self._zero_target(t)
        return True

    def _zero_target(self, t: float) -> None:
        """A zero velocity and turn-rate target (ArduPilot, GUIDED; PX4, Offboard): the rover brakes to a stand."""
        assert self.enc is not None
        self.send_message(self.steering.zero(self.enc, self.seen, t))

    def send_message(self, msg, enc: apm.MAVLink | None = None) -> None:
        """One message to the autopilot, as the companion (or through ``enc``, as the keepalive's sender)."""
        enc = enc or self.enc
        assert enc is not None
        self.send(bytes(msg.pack(enc)))
        enc.seq = (enc.seq + 1) % 256
