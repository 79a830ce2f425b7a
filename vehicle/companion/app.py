"""The companion's loop: the native vehicle (``Vehicle`` + ``Endpoint``) on an autopilot, with a router in front.

Everything that decides runs the native code: the lease book, the link watch, the trail, the return service and
navigator live in the native vehicle core, which the companion boots (``vehicle.core``) and then sees only through
its port (``vehicle.port.VehiclePort``: the command authority, the status snapshot, the event queue); component 191
is ``vehicle.endpoint.Endpoint`` composing the native microservices (``vehicle.services``) with the companion's
identity, the streams it owns and no teleop (``SERVICES``). What is added is only what sits between two links:
``router`` decides what of the ground's traffic the autopilot may hear, ``AutopilotDriver`` turns the autopilot into
the vehicle's robot, and ``GroundVoice`` relays the autopilot to the ground. No clock and no socket: bytes come in
through ``from_autopilot`` / ``from_ground``, go out through the two callables given, and ``tick(t)`` runs the 50 Hz
loop at the time it is given, so the same object runs under ``returnlink companion`` (wall clock, real links) and in
a lockstep simulation.

The vehicle boots once the autopilot has said where it is (its EKF reports a horizontal position), on that pose,
so the trail never starts at a made-up origin. Until then reads pass and state changes are answered
TEMPORARILY_REJECTED.

The rover's range data (``vehicle.companion.ranges``, read by ``AutopilotDriver``) is the vehicle's range sensor. The
companion says once what it hears: the sources of the first range data, or, QUIET_S after it booted with none
heard, that the return keeps no standoff (everything else as without the sensors). Range data is relayed to the
ground at most once every RANGE_RELAY_S per sensor: the return asks for it at 10 Hz, six rangefinders are 60
messages a second, and a telemetry radio has better uses for its air time.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Hashable
from functools import partial
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

from link.mission import Origin
from link.signing import Key, SigningVerdict, Streams, sim_stamp
from vehicle.companion import router
from vehicle.companion.autopilot import AutopilotDriver, is_autopilot_heartbeat, rover_problem
from vehicle.companion.ranges import KINDS as RANGE_KINDS
from vehicle.companion.ranges import QUIET_S
from vehicle.companion.router import COMPANION_COMPID, Action, Authority, Decision, Dest
from vehicle.companion.voice import GroundVoice, frame_msgid
from vehicle.core import boot_core
from vehicle.endpoint import Endpoint
from vehicle.keystore import KeyStore, boot_stamp
from vehicle.lease import ExpireReason, Holder, LeaseBook
from vehicle.params import Params
from vehicle.port import VehiclePort
from vehicle.radio_status import KINDS as RADIO_REPORTS
from vehicle.radio_status import rssi_dbm
from vehicle.services.native import vehicle_services
from vehicle.services.telemetry import DEFAULT_RATES

NOTICE_GAP = 2.0  # s between STATUSTEXTs about the same refused stream from the same sender
RANGE_RELAY_S = 1.0  # s between one sensor's range messages relayed to the ground (the return reads all of them)
# the endpoint's own reports of what the autopilot reports for the same system: the autopilot's copy reaches the
# ground already, and ground stations keep one value per message type and system, so a second copy from component
# 191 would make their position, health, mode and mission progress flicker between the two (the return's progress
# is in LEASE_STATUS)
DUPLICATES = frozenset((apm.MAVLINK_MSG_ID_SYS_STATUS, apm.MAVLINK_MSG_ID_GPS_RAW_INT, apm.MAVLINK_MSG_ID_ATTITUDE,
                        apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED, apm.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                        apm.MAVLINK_MSG_ID_HOME_POSITION, apm.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                        apm.MAVLINK_MSG_ID_MISSION_CURRENT, apm.MAVLINK_MSG_ID_MISSION_ITEM_REACHED,
                        436))  # CURRENT_MODE (development.xml)

# component 191's microservices: the native vehicle's, streaming only what the autopilot does not report itself
# (lease and control status), and without teleop: setpoints are the autopilot's business (component 1)
OWN_STREAMS = {msgid: interval for msgid, interval in DEFAULT_RATES.items() if msgid not in DUPLICATES}
SERVICES = partial(vehicle_services, rates=OWN_STREAMS, drives=False)

# the owner's drive of the autopilot in GUIDED: what the dead-man watches (MANUAL_CONTROL and RC override have the
# autopilot's own override timeout, RC_OVERRIDE_TIME)
SETPOINTS = frozenset(("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT"))
STOP_RESEND = 1.0  # s between repeated stops while the owner stays silent (one may be lost on the wire)
HOLD_GAPS = 1.0  # the dead-man waits no shorter than the owner's longest recent gap between packets
RHYTHM_S = 5.0  # s: the owner's gaps between packets over this long are its rhythm
STREAM_S = 2.5  # s: the owner counts as driving with setpoints if it sent one this long before its last packet


def drive_held(t: float, setpoint_at: float | None, owner_heard: float | None, hold_s: float,
               rhythm: float) -> bool:
    """The companion's dead-man (LNK_HOLD_S): the owner was driving the autopilot with setpoints (one within
    STREAM_S of its last packet) and has been silent ``hold_after(hold_s, rhythm)``.

    The native vehicle drops a teleop setpoint 0.5 s after its stream stops; an autopilot drives on to the owner's
    last position target for as long as nobody says otherwise, which before this rule was the whole LNK_TIMEOUT
    before the return took it back (issue 28: some 3 m past the loss in the tunnel, 6 m on a field). Silence (no
    packet at all, heartbeats included) is the test, so an owner is not held while its 1 Hz heartbeat arrives
    (LNK_HOLD_S 1 s by default, a heartbeat's period; a stick let go while the heartbeat goes on is the autopilot's
    own business, its velocity targets time out in 3 s). Below that a fixed time trips on sparse senders
    (measured: at 0.7 s the scripted GUIDED operator, a heartbeat a second and a target a metre, was stopped
    between its packets and never got going); above it the owner's own rhythm (``rhythm``: its longest gap
    between its packets over the last RHYTHM_S, the radio's holes taken out: ``Companion._rhythm``) lets an owner
    that sends sparsely drive. Measured on companion.toml's five worlds (50 trials each): LNK_HOLD_S 1.25 fixed,
    P95 to link 6.3-17.2 s; 1.25 with 1.25x the rhythm, 6.3-20.8 s; 1 with the rhythm counting the radio's holes,
    6.3-13.3 s; 1 with the owner's own rhythm, see the README's companion table. An owner that sent
    one goal and then only its heartbeat is not streaming: the autopilot drives on to the goal, and LNK_TIMEOUT
    governs."""
    if hold_s <= 0 or setpoint_at is None or owner_heard is None or owner_heard - setpoint_at > STREAM_S:
        return False
    return t - owner_heard >= hold_after(hold_s, rhythm)


def hold_after(hold_s: float, rhythm: float) -> float:
    """Seconds of the owner's silence after which the dead-man holds the drive (see ``drive_held``)."""
    return max(hold_s, HOLD_GAPS * rhythm)


class Companion:
    """returnlink beside an ArduPilot Rover or a PX4 rover (which one, its first HEARTBEAT says: ``AutopilotDriver``).
    Build it, feed it bytes, tick it at 50 Hz (see the module docstring)."""

    def __init__(self, params: Params, to_autopilot: Callable[[bytes], None], to_ground: Callable[[bytes], None],
                 *, key: Key | None = None, keystore: KeyStore | None = None,
                 stamp: Callable[[float], int] = sim_stamp, boot_epoch: int | None = None, seed: int = 0,
                 param_file: Path | None = None, on_epoch: Callable[[int], str | None] | None = None,
                 autopilot_name: str = "the autopilot", pivots: bool = False) -> None:
        """``params``: the companion's returnlink parameters. ``key`` (or ``keystore``, which also keeps the signing
        timestamp on disk) signs the ground side (docs/architecture.md §4.1), ``stamp(t)`` is its clock.
        ``boot_epoch`` None derives the first epoch from ``seed`` (lockstep simulation only); ``on_epoch`` is told of
        each epoch issued (``vehicle.epochs.EpochLog.issued``). ``autopilot_name`` names the autopilot link in
        messages."""
        self.params = params
        self.to_autopilot, self.to_ground = to_autopilot, to_ground
        self.keystore = keystore
        self.key = keystore.key if keystore is not None else key
        self.stamp = stamp
        self.boot_epoch, self.seed = boot_epoch, seed
        self.param_file, self.on_epoch = param_file, on_epoch
        self.autopilot_name = autopilot_name
        self.driver = AutopilotDriver(to_autopilot, pivots)
        self.vehicle: VehiclePort | None = None
        self.endpoint: Endpoint | None = None
        saved = keystore.saved_stamp if keystore is not None else None
        self.voice = GroundVoice(self.key, stamp, boot_stamp(saved, stamp(0.0)))
        self.ap_parser = apm.MAVLink(None, 0, 0)
        self.ap_parser.robust_parsing = True
        self.ground_parser = apm.MAVLink(None, 0, 0)
        self.ground_parser.robust_parsing = True
        self.streams = Streams()
        self.t = 0.0
        self.identity_problem: str | None = None  # the autopilot is not an ArduPilot Rover
        self.autopilot_lost = False
        self.healthy = True
        self.mode_from_ground = False  # a ground station changed the autopilot's mode during this engagement
        self.preempted = False
        self.sources: dict[int, Hashable] = {}  # ground sysid -> where its last trusted frame came from
        self.notice_at: dict[tuple[int, str], float] = {}
        self.counters = {"forwarded": 0, "refused": 0, "relayed": 0, "bad_frames": 0, "drive_held": 0}
        self.setpoint_at: float | None = None  # the owner's last setpoint forwarded to the autopilot
        self.gaps: deque[tuple[float, float]] = deque()  # (arrival, gap before it) of the owner's recent packets
        self.heard_at: float | None = None  # the owner's last packet, as the rhythm last saw it
        self.heard_seq: int | None = None  # its unwrapped sequence number (None: not measured)
        self.stopped_at: float | None = None  # the dead-man's last stop (None: not holding)
        # PX4: the owner's Offboard drive went to Hold (the dead-man, or PX4's own Offboard loss) and its next
        # setpoint asks for Offboard again (``_resume_drive``); the mode last seen, and a ground mode change's time
        self.held_drive = False
        self.last_mode: int | None = None
        self.ground_mode_at: float | None = None
        self.booted_at: float | None = None
        self.ranges_said: str | None = None  # what the companion said of the range data: "heard", "none" (once each)
        self.range_relayed: dict[tuple, float] = {}  # (sysid, compid, message, sensor) -> when last relayed

    # ----- input -----------------------------------------------------------------------------------------------
    def from_autopilot(self, data: bytes, t: float) -> None:
        """Bytes from the autopilot's link: observed, and relayed to the ground (all but answers addressed to the
        companion itself)."""
        try:
            msgs = self.ap_parser.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - a garbled stream must not stop the companion
            self.counters["bad_frames"] += 1
            self.ap_parser = apm.MAVLink(None, 0, 0)
            self.ap_parser.robust_parsing = True
            return
        d = self.driver
        for m in msgs:
            if m.get_type() == "BAD_DATA":
                self.counters["bad_frames"] += 1
                continue
            d.observe(m, t)
            if d.seen.sysid is not None and self.identity_problem is None and is_autopilot_heartbeat(m) \
                    and m.get_srcSystem() == d.seen.sysid:
                self.identity_problem = rover_problem(m)
            if self._for_companion(m) or (m.get_type() in RANGE_KINDS and not self._relay_range(m, t)):
                continue
            self.to_ground(self.voice.relay(m))
            self.counters["relayed"] += 1

    def _relay_range(self, m, t: float) -> bool:
        """Whether this range message goes on to the ground: a sensor's first in RANGE_RELAY_S."""
        key = (m.get_srcSystem(), m.get_srcComponent(), m.get_type(), getattr(m, "id", 0),
               getattr(m, "orientation", 0))
        if t - self.range_relayed.get(key, -math.inf) < RANGE_RELAY_S:
            return False
        if len(self.range_relayed) >= 1024:  # (a vehicle has a few dozen sensors: anything more is noise)
            self.range_relayed.clear()
        self.range_relayed[key] = t
        return True

    def _for_companion(self, m) -> bool:
        fields = m.get_fieldnames()
        return ("target_system" in fields and "target_component" in fields
                and m.target_system == self.driver.seen.sysid and m.target_component == COMPANION_COMPID)

    def from_ground(self, data: bytes, t: float, source: Hashable | None = None) -> None:
        """Bytes from the ground side (``source``: where they came from, e.g. a UDP address): each frame to the
        companion's endpoint, to the autopilot, or refused and answered."""
        try:
            msgs = self.ground_parser.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - a hostile byte stream must never take the companion down
            self.counters["bad_frames"] += 1
            self.ground_parser = apm.MAVLink(None, 0, 0)
            self.ground_parser.robust_parsing = True
            return
        for m in msgs:
            try:
                self._ground_frame(m, t, source)
            except Exception as e:  # noqa: BLE001 - one absurd frame is refused, never fatal
                self.counters["bad_frames"] += 1
                self.notice(0, "fault", f"ground frame {m.get_type()} dropped: {type(e).__name__}: {e}", t)

    def _ground_frame(self, m, t: float, source: Hashable | None) -> None:
        if m.get_type() == "BAD_DATA":
            self.counters["bad_frames"] += 1
            return
        header = m.get_header()
        sender, scomp = header.srcSystem, header.srcComponent
        sysid = self.driver.seen.sysid
        if sender == 0 or sysid is None or sender == sysid:
            return  # anonymous, before the autopilot is known, or the vehicle's own frames come back
        if m.get_type() in RADIO_REPORTS:
            # the telemetry radio's report (any sender: SiK radios are 51/68, and cannot sign, so it counts signed
            # or not, as ArduPilot accepts it unsigned): its local RSSI is the owner's signal at the robot, for the
            # link map and the crumbs (never the loss trigger). Then on to the endpoint as before (Dest.KEEP)
            dbm = rssi_dbm(m)
            counted = "radio_ignored" if dbm is None else "radio_reports"
            self.counters[counted] = self.counters.get(counted, 0) + 1
            if dbm is not None and self.vehicle is not None:
                self.vehicle.radio_rssi(dbm, t)
        raw = bytes(m.get_msgbuf())
        trusted = True
        if self.key is not None:
            self.streams, verdict = self.streams.verify(self.key, raw, self.voice.enc.signing.timestamp)
            trusted = verdict is SigningVerdict.ACCEPT
        if trusted and source is not None:
            self.sources[sender] = source
        r = router.route(m, sysid)
        v, ep = self.vehicle, self.endpoint
        if r.dest in (Dest.COMPANION, Dest.KEEP):
            if ep is not None:
                ep.receive(raw, t, source)  # the endpoint judges signatures and hears the owner itself
            elif r.dest is Dest.COMPANION:
                self.notice(sender, "starting", "returnlink companion is starting: waiting for the autopilot's "
                             "position estimate", t)
            return
        if trusted and v is not None:
            v.heard(sender, t, header.seq)
        if r.dest is Dest.MISDIRECTED:
            self._refuse(m, Decision(Action.REFUSE, apm.MAV_RESULT_DENIED, f"{router.what(m)} moves the robot: send "
                                     f"it to the autopilot (component 1), not to the companion (191)"), sender, scomp,
                         t)
            return
        if r.dest is Dest.SIGNING:
            self.notice(sender, "signing", "signing setup refused: the companion's key is changed by restarting "
                         "it with --key FILE", t)
            return
        if r.dest is not Dest.AUTOPILOT:
            return
        d = self._decide(m, r.authority, sender, scomp, t, trusted)
        if d.kind is Action.FORWARD:
            self.to_autopilot(raw)
            self.counters["forwarded"] += 1
            if r.authority is Authority.MODE:
                self.mode_from_ground, self.held_drive, self.ground_mode_at = True, False, t
                self.driver.stop_braking()  # the owner chose the mode: the brake after a return is done
            elif m.get_type() in SETPOINTS:
                self.setpoint_at, self.stopped_at = t, None
                self.driver.stop_braking()  # the owner drives again: its targets, not the brake's
                if self.held_drive:
                    self._resume_drive(t)
            return
        self._refuse(m, d, sender, scomp, t)

    def _decide(self, m, access: Authority, sender: int, scomp: int, t: float, trusted: bool) -> Decision:
        """The router's decision, with the vehicle asked where the native endpoint asks it (admit, take_manual)."""
        if access is Authority.READ:
            return router.FORWARD
        v = self.vehicle
        if v is None:
            return Decision(Action.REFUSE, apm.MAV_RESULT_TEMPORARILY_REJECTED,
                            "the companion is starting (waiting for the autopilot's position estimate)")
        if self.autopilot_lost:
            return Decision(Action.REFUSE, apm.MAV_RESULT_TEMPORARILY_REJECTED,
                            f"{self.autopilot_name} is not answering")
        keyed = self.key is not None
        d = router.decide(access, sender, scomp, v.status().book, t, trusted=trusted, keyed=keyed)
        if d.kind is Action.ADMIT:
            v.admit(sender, scomp, t)
            d = router.decide(access, sender, scomp, v.status().book, t, trusted=trusted, keyed=keyed)
            if d.kind is Action.ADMIT:  # (cannot happen: the grant was just decided possible)
                d = Decision(Action.REFUSE, apm.MAV_RESULT_DENIED, "not granted")
        if d.kind is Action.TAKE:
            chk = v.take_manual(sender, scomp, t)
            if chk.executes:
                return router.FORWARD
            reason = chk.reason or router.RejectReason.INVALID
            return Decision(Action.REFUSE, router.REJECT_RESULT[reason],
                            f"{chk.detail or reason.value}; {router.lease_text(v.status().book)}")
        if d.kind is Action.REFUSE and self.vehicle is not None:
            self.vehicle.refused()  # (take_manual counts its own refusals)
        return d

    def _refuse(self, m, d: Decision, sender: int, scomp: int, t: float) -> None:
        self.counters["refused"] += 1
        sysid = self.driver.seen.sysid
        assert sysid is not None
        replies = router.answers(m, sender, scomp, d.result)
        for comp, msg in replies.to_ground:
            self.to_ground(self.voice.say(sysid, comp, msg))
        for msg in replies.to_autopilot:
            self.driver.send_message(msg)
        what = router.what(m)
        self.notice(sender, what, f"{what} from {sender} refused: {d.why}", t)

    def notice(self, sender: int, topic: str, text: str, t: float) -> None:
        """A STATUSTEXT to the ground, at most every NOTICE_GAP s per sender and topic (streams are refused at
        10 Hz): through the endpoint once it runs, in the companion's name before."""
        key = (sender, topic)
        if t - self.notice_at.get(key, -math.inf) < NOTICE_GAP:
            return
        self.notice_at[key] = t
        if self.vehicle is not None:
            self.vehicle.announce(text)
        elif self.driver.seen.sysid is not None:
            msg = apm.MAVLink_statustext_message(apm.MAV_SEVERITY_WARNING, text.encode()[:50])
            self.to_ground(self.voice.say(self.driver.seen.sysid, COMPANION_COMPID, msg))

    # ----- the loop ------------------------------------------------------------------------------------------
    def tick(self, t: float) -> None:
        """One 50 Hz tick at time ``t``: the autopilot's health, the vehicle (booted once it can be), the return's
        hold on the autopilot, the keepalive, and the endpoint's frames to the ground."""
        self.t = t
        self.voice.tick(t)
        d = self.driver
        self._watch_autopilot(t)
        if self.vehicle is None and d.ready() and self.identity_problem is None:
            self._boot(t)
        self.healthy = self._tick_vehicle(t) if self.vehicle is not None else True
        if self.vehicle is not None and self.ranges_said != "heard":
            self._say_ranges(t)
        why = d.tick(t, self.healthy)
        if why is not None and self.vehicle is not None:
            self.preempted = True
            self.vehicle.preempt(t, ExpireReason.OPERATOR_EXPIRE, why)
        if self.endpoint is not None:
            for frame in self.endpoint.tick(t):
                if frame_msgid(frame) not in DUPLICATES:
                    self.to_ground(frame)

    def _boot(self, t: float) -> None:
        d = self.driver
        origin = Origin(*d.seen.origin) if d.seen.origin is not None else Origin()
        v = boot_core(d, self.params, d.pose(), t, seed=self.seed, boot_epoch=self.boot_epoch, on_epoch=self.on_epoch)
        ep = Endpoint(v, sysid=d.seen.sysid or 1, compid=COMPANION_COMPID, origin=origin, boot_t=t,
                      param_file=self.param_file, key=None if self.keystore else self.key, keystore=self.keystore,
                      stamp=self.stamp, services=SERVICES, mav_type=apm.MAV_TYPE_ONBOARD_CONTROLLER,
                      autopilot=apm.MAV_AUTOPILOT_INVALID)
        self.vehicle, self.endpoint = v, ep
        self.booted_at = t
        x, y, yaw = d.pose()
        v.announce(f"returnlink companion on {self.autopilot_name}: vehicle at ({x:.1f}, {y:.1f}) m, "
                         f"heading {math.degrees(yaw) % 360:.0f} deg")

    def _say_ranges(self, t: float) -> None:
        """Once: the range data the return keeps off (its sources), or that none came in QUIET_S (then once more
        if some comes later)."""
        v, ranges = self.vehicle, self.driver.ranges
        assert v is not None and self.booted_at is not None
        if ranges.first_heard is not None:
            self.ranges_said = "heard"
            body = v.params["RTL_BODY_R"]
            keeps = (f"the return keeps its {body:g} m body off what they see" if body > 0 else
                     "but RTL_BODY_R is 0: the return keeps no standoff")
            v.announce(f"range sensor heard ({ranges.describe()}): {keeps}")
        elif self.ranges_said is None and t - self.booted_at >= QUIET_S:
            self.ranges_said = "none"
            v.announce("no range sensor heard: return keeps no standoff")

    def _tick_vehicle(self, t: float) -> bool:
        """The vehicle's own tick, then the return's hold on the autopilot. False: the tick failed (reported,
        and the keepalive withheld so the autopilot's failsafe takes over if it keeps failing)."""
        v, d = self.vehicle, self.driver
        assert v is not None
        v.robot_armed(d.armed)  # the autopilot arms itself: the vehicle follows
        try:
            v.tick(t)
        except Exception as e:  # noqa: BLE001 - reported and withheld from the keepalive, never fatal
            self.notice(0, "tick", f"companion loop fault: {type(e).__name__}: {e}; keepalive withheld", t)
            return False
        book = v.status().book
        returning = book.returning and not self.autopilot_lost
        if returning and not d.engaged and d.armed:
            self.mode_from_ground = self.preempted = False
            d.engage(t)
        elif not returning and d.engaged:
            d.release(t, hold=not (self.mode_from_ground or self.preempted))
        rhythm = self._rhythm(book.link.last_heard, book.link.delivery.newest, v.params["LNK_TIMEOUT"])
        if not returning:
            self._dead_man(t, rhythm, book)
        self._watch_held(t, book, returning)
        return True

    def _watch_held(self, t: float, book: LeaseBook, returning: bool) -> None:
        """PX4: note when the owner's Offboard drive went to Hold without anyone on the ground asking (PX4's
        Offboard loss: the owner's stream silent for COM_OF_LOSS_T), so that its next setpoint resumes it
        (``_resume_drive``); forget it once the rover is in any other mode or a return holds the lease."""
        d = self.driver
        mode, rules = d.seen.mode, d.rules
        cur = book.current
        if (rules.stop_holds and not returning and self.last_mode == rules.drive and mode == rules.hold
                and cur is not None and cur.holder is Holder.OPERATOR and cur.claimed and self.setpoint_at is not None
                and t - self.setpoint_at <= STREAM_S
                and (self.ground_mode_at is None or t - self.ground_mode_at > STREAM_S)):
            self.held_drive = True
        if returning or mode not in (rules.drive, rules.hold):
            self.held_drive = False
        self.last_mode = mode

    def _resume_drive(self, t: float) -> None:
        """The owner's setpoint arrived (forwarded: it holds the current lease) while its Offboard drive stands
        in a Hold it did not ask for: Offboard again, as ArduPilot drives again on the owner's next target after
        the dead-man's stop. The companion knows whose lease is current; the owner's station, a radio hop away,
        may not (a mode change from it over a return that began meanwhile would take the lease from the return)."""
        d = self.driver
        if d.seen.mode == d.rules.hold and not d.engaged:
            self.held_drive = False
            d.resume(t)

    def _dead_man(self, t: float, rhythm: float, book: LeaseBook) -> None:
        """Stop the autopilot's drive once the owner driving it with setpoints has fallen silent (``drive_held``):
        a zero-velocity target, repeated every STOP_RESEND s while the silence lasts. The owner's next setpoint
        drives again; a return that follows finds the autopilot in GUIDED and standing (PX4: in Hold, which the
        return leaves for Offboard once its own stream runs; ``AutopilotDriver.stop``)."""
        v, d = self.vehicle, self.driver
        assert v is not None
        heard = book.link.last_heard
        cur = book.current
        if (cur is None or cur.holder is not Holder.OPERATOR or not d.armed or self.autopilot_lost
                or not drive_held(t, self.setpoint_at, heard, v.params["LNK_HOLD_S"], rhythm)):
            return
        if self.stopped_at is not None and t - self.stopped_at < STOP_RESEND:
            return
        if d.stop(t):
            self.held_drive = self.held_drive or d.rules.stop_holds  # (PX4: the owner's next setpoint resumes)
            if self.stopped_at is None:
                self.counters["drive_held"] += 1
                self.notice(0, "dead-man", f"owner silent {t - (heard or t):.1f} s: the autopilot's drive "
                                           f"stopped (LNK_HOLD_S)", t)
            self.stopped_at = t

    def _rhythm(self, heard: float | None, seq: int | None, timeout: float) -> float:
        """The owner's own longest spacing between packets over the RHYTHM_S before its last one (0: none
        known): each gap between two packets heard, divided by the packets it sent in it (their MAVLink sequence
        numbers, ``seq`` the newest heard; 1 where they are not measured). A hole the radio made is not the
        owner's rhythm: the packets it swallowed were sent, and counting the hole let the autopilot drive on to a
        stale target at the fringe (issue 28, the open field: 6-12 m deeper before the loss, a longer way back). A
        gap of LNK_TIMEOUT or more was a loss, not a rhythm at all."""
        if heard is None:
            return 0.0
        gaps = self.gaps
        if heard != self.heard_at:
            if self.heard_at is not None and heard - self.heard_at < timeout:
                sent = 1 if seq is None or self.heard_seq is None else seq - self.heard_seq
                if sent > 0:
                    gaps.append((heard, (heard - self.heard_at) / sent))
            self.heard_at, self.heard_seq = heard, seq
            while gaps and gaps[0][0] < heard - RHYTHM_S:
                gaps.popleft()
        return max((g for _, g in gaps), default=0.0)

    def _watch_autopilot(self, t: float) -> None:
        """The autopilot silent for LOST_AFTER: said to the ground, and whatever lease was current ends (nothing
        it allowed can reach the robot); heard again: said too."""
        d = self.driver
        lost = d.seen.heard is not None and d.lost(t)
        if lost == self.autopilot_lost:
            return
        self.autopilot_lost = lost
        if lost:
            why = f"{self.autopilot_name} lost: no message for {t - (d.seen.heard or t):.1f} s; retrying"
            if d.engaged:
                d.release(t, hold=False)
            if self.vehicle is None or not self.vehicle.preempt(t, ExpireReason.STUCK, why):
                self.notice(0, "autopilot lost", why, t)
        else:
            self.notice(0, "autopilot back", f"{self.autopilot_name} answering again", t)

    # ----- for the shell -----------------------------------------------------------------------------------------
    def pinned(self) -> list[Hashable]:
        """Ground addresses a transport must keep: the owner's (docs/architecture.md §3.9)."""
        owner = self.vehicle.status().book.owner if self.vehicle is not None else None
        if owner is None or owner not in self.sources:
            return []
        return [self.sources[owner]]

    def close(self) -> None:
        """Shutdown: the signing timestamp to disk."""
        if self.endpoint is not None:
            self.endpoint.close(self.t)
