"""The companion's loop: the native vehicle (``Vehicle`` + ``Endpoint``) on an autopilot, with a router in front.

Everything that decides runs the native code: the lease book, the link watch, the trail, the return service and
navigator live in the native vehicle core, which the companion boots (``vehicle.core``) and then sees only through
its port (``vehicle.port.VehiclePort``: the command authority, the status snapshot, the event queue); component 191
is ``vehicle.endpoint.Endpoint`` composing the native microservices (``vehicle.services``) with the companion's
identity, the streams it owns and no teleop (``SERVICES``). What is added is only what sits between two links, each
in its own module: on the ground side ``router`` decides what of the ground's traffic the autopilot may hear and
``gate`` asks the vehicle's port where the router says to, and ``GroundVoice`` relays the autopilot to the ground; on
the vehicle side ``AutopilotDriver`` turns the autopilot into the vehicle's robot and ``DriveWatch`` holds the
owner's drive when the owner falls silent (the dead-man, LNK_HOLD_S). This class wires them: frames in, the tick,
frames out. No clock and no socket: bytes come in
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
from collections.abc import Callable, Hashable
from functools import partial
from pathlib import Path
from typing import NamedTuple

from pymavlink.dialects.v20 import ardupilotmega as apm

from link.mission import Origin
from link.signing import Key, SigningVerdict, Streams, sim_stamp
from vehicle.companion import gate, router
from vehicle.companion.autopilot import AutopilotDriver
from vehicle.companion.drive_watch import SETPOINTS, DriveWatch
from vehicle.companion.ranges import KINDS as RANGE_KINDS
from vehicle.companion.ranges import QUIET_S
from vehicle.companion.router import COMPANION_COMPID, Action, Authority, Decision, Dest, Routing
from vehicle.companion.rules import is_autopilot_heartbeat, rover_problem
from vehicle.companion.voice import GroundVoice, RangeRelay, frame_msgid
from vehicle.core import Core, boot_core
from vehicle.endpoint import Endpoint
from vehicle.keystore import KeyStore, boot_stamp
from vehicle.lease import ExpireReason
from vehicle.params import Params
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


def parser() -> apm.MAVLink:
    """A MAVLink parser that skips garbage rather than raising on it (a link is a wire, or a radio)."""
    mav = apm.MAVLink(None, 0, 0)
    mav.robust_parsing = True
    return mav


class GroundFrame(NamedTuple):
    """A frame from the ground as the companion judged it: its bytes, who sent it, from where, and whether its
    signature holds (always, without a key)."""

    m: object
    raw: bytes
    sender: int
    scomp: int
    seq: int
    source: Hashable | None
    trusted: bool


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
        self.vehicle: Core | None = None
        self.endpoint: Endpoint | None = None
        saved = keystore.saved_stamp if keystore is not None else None
        self.voice = GroundVoice(self.key, stamp, boot_stamp(saved, stamp(0.0)))
        self.ap_parser, self.ground_parser = parser(), parser()
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
        self.drive = DriveWatch(self.driver)  # the dead-man over the owner's drive, PX4's held Offboard
        self.booted_at: float | None = None
        self.ranges_said: str | None = None  # what the companion said of the range data: "heard", "none" (once each)
        self.range_relay = RangeRelay(RANGE_RELAY_S)

    # ----- input -----------------------------------------------------------------------------------------------
    def from_autopilot(self, data: bytes, t: float) -> None:
        """Bytes from the autopilot's link: observed, and relayed to the ground (all but answers addressed to the
        companion itself)."""
        try:
            msgs = self.ap_parser.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - a garbled stream must not stop the companion
            self.counters["bad_frames"] += 1
            self.ap_parser = parser()
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
            if self._for_companion(m) or (m.get_type() in RANGE_KINDS and not self.range_relay.passes(m, t)):
                continue
            self.to_ground(self.voice.relay(m))
            self.counters["relayed"] += 1

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
            self.ground_parser = parser()
            return
        for m in msgs:
            try:
                self._ground_frame(m, t, source)
            except Exception as e:  # noqa: BLE001 - one absurd frame is refused, never fatal
                self.counters["bad_frames"] += 1
                self.notice(0, "fault", f"ground frame {m.get_type()} dropped: {type(e).__name__}: {e}", t)

    def _ground_frame(self, m, t: float, source: Hashable | None) -> None:
        """One frame from the ground: the radio's report noted, its signature judged, then where the router sends
        it (``_ROUTES``: one small handler a destination)."""
        if m.get_type() == "BAD_DATA":
            self.counters["bad_frames"] += 1
            return
        header = m.get_header()
        sysid = self.driver.seen.sysid
        if header.srcSystem == 0 or sysid is None or header.srcSystem == sysid:
            return  # anonymous, before the autopilot is known, or the vehicle's own frames come back
        if m.get_type() in RADIO_REPORTS:
            self._radio_report(m, t)
        raw = bytes(m.get_msgbuf())
        trusted = True
        if self.key is not None:
            self.streams, verdict = self.streams.verify(self.key, raw, self.voice.enc.signing.timestamp)
            trusted = verdict is SigningVerdict.ACCEPT
        if trusted and source is not None:
            self.sources[header.srcSystem] = source
        frame = GroundFrame(m, raw, header.srcSystem, header.srcComponent, header.seq, source, trusted)
        r = router.route(m, sysid)
        if r.dest not in (Dest.COMPANION, Dest.KEEP) and trusted and self.vehicle is not None:
            self.vehicle.heard(frame.sender, t, frame.seq)  # (the endpoint hears the owner itself)
        self._ROUTES[r.dest](self, frame, r, t)

    def _radio_report(self, m, t: float) -> None:
        """The telemetry radio's report (any sender: SiK radios are 51/68, and cannot sign, so it counts signed or
        not, as ArduPilot accepts it unsigned): its local RSSI is the owner's signal at the robot, for the link map
        and the crumbs (never the loss trigger). Then on to the endpoint as before (Dest.KEEP)."""
        dbm = rssi_dbm(m)
        counted = "radio_ignored" if dbm is None else "radio_reports"
        self.counters[counted] = self.counters.get(counted, 0) + 1
        if dbm is not None and self.vehicle is not None:
            self.vehicle.radio_rssi(dbm, t)

    def _to_endpoint(self, f: GroundFrame, r: Routing, t: float) -> None:
        """For the companion's own endpoint, which judges signatures and hears the owner itself."""
        if self.endpoint is not None:
            self.endpoint.receive(f.raw, t, f.source)
        elif r.dest is Dest.COMPANION:
            self.notice(f.sender, "starting", "returnlink companion is starting: waiting for the autopilot's "
                        "position estimate", t)

    def _misdirected(self, f: GroundFrame, r: Routing, t: float) -> None:
        self._refuse(f.m, Decision(Action.REFUSE, apm.MAV_RESULT_DENIED, f"{router.what(f.m)} moves the robot: send "
                                   f"it to the autopilot (component 1), not to the companion (191)"), f.sender,
                     f.scomp, t)

    def _signing(self, f: GroundFrame, r: Routing, t: float) -> None:
        self.notice(f.sender, "signing", "signing setup refused: the companion's key is changed by restarting "
                    "it with --key FILE", t)

    def _elsewhere(self, f: GroundFrame, r: Routing, t: float) -> None:
        """Addressed to another system or component: dropped."""

    def _to_autopilot(self, f: GroundFrame, r: Routing, t: float) -> None:
        """For the autopilot: forwarded if the sender may (``gate.decide``), else refused and answered. The owner's mode
        change or setpoint reaching the autopilot ends the brake after a return and tells the drive watch."""
        down = f"{self.autopilot_name} is not answering" if self.autopilot_lost else None
        d = gate.decide(self.vehicle, r.authority, f.sender, f.scomp, t, trusted=f.trusted, keyed=self.key is not None,
                        autopilot_down=down)
        if d.kind is not Action.FORWARD:
            self._refuse(f.m, d, f.sender, f.scomp, t)
            return
        self.to_autopilot(f.raw)
        self.counters["forwarded"] += 1
        if r.authority is Authority.MODE:
            self.mode_from_ground = True
            self.drive.mode_changed(t)
            self.driver.stop_braking()  # the owner chose the mode: the brake after a return is done
        elif f.m.get_type() in SETPOINTS:
            self.driver.stop_braking()  # the owner drives again: its targets, not the brake's
            self.drive.setpoint(t)

    _ROUTES = {Dest.COMPANION: _to_endpoint, Dest.KEEP: _to_endpoint, Dest.MISDIRECTED: _misdirected,
               Dest.SIGNING: _signing, Dest.AUTOPILOT: _to_autopilot, Dest.ELSEWHERE: _elsewhere}

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
        said = self.drive.tick(t, book, returning, v.params["LNK_HOLD_S"], v.params["LNK_TIMEOUT"],
                               self.autopilot_lost)
        if said is not None:
            self.counters["drive_held"] += 1
            self.notice(0, "dead-man", said, t)
        return True

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
