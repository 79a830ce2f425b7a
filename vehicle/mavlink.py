"""The MAVLink endpoint of the vehicle (DESIGN §4): bytes in, bytes out, nothing else.

It parses frames with the generated ``returnlink`` dialect, enforces target ids, maps each standard message or
command onto a ``Vehicle`` method (where the lease rules decide), answers every command exactly once, runs the
mission and parameter protocols, and schedules telemetry. It owns no clock and no socket: ``receive(data, t)``
and ``tick(t) -> [frames]`` are called by whatever loop drives the vehicle.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import NamedTuple

from link import dialect
from link.codec import read_frames
from link.command_params import check_command, command_name, command_values
from link.mission import Item, Origin, item_from_message
from link.plan_items import (
    MISSION_INVALID_PARAM,
    NAV_RETURN_TO_LINK,
    ItemError,
    ItemFault,
    position_scale,
)
from link.signing import MAX_TIMESTAMP, Key, Streams, advance, enable, sim_stamp, timestamp_of
from link.signing import Verdict as SignVerdict
from vehicle.app import MAX_TELEOP_SPEED, MAX_TELEOP_YAW_RATE, Vehicle, velocity_to_command
from vehicle.keystore import STAMP_SAVE_EVERY, KeyStore, boot_stamp
from vehicle.lease import Check, RejectReason, Verdict
from vehicle.missions import ACCEPTED, DENIED, INVALID, UNSUPPORTED, MissionServer, to_plan
from vehicle.modes import decode_mode
from vehicle.params import SPECS, ParamError, save_parm
from vehicle.retries import RetryWindow, command_key
from vehicle.service import PlanItem
from vehicle.telemetry import MSG_ID_AVAILABLE_MODES, Telemetry, wire_index

mav = dialect.load()

RETRY_WINDOW = 3.0  # s: an identical command from the same sender within this is a retry or a late copy
BODY_FRAMES = frozenset((mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_FRD))
REJECT_NOTICE_GAP = 2.0  # s between STATUSTEXTs about a rejected stream (MANUAL_CONTROL, velocity targets)

# MAVLink FTP (FILE_TRANSFER_PROTOCOL payload): this vehicle has no file server; it says so at once
FTP_OP_NAK, FTP_ERR_UNKNOWN_COMMAND = 129, 7
FTP_HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, padding, offset

REJECT_RESULT = {
    RejectReason.NOT_IN_CONTROL: mav.MAV_RESULT_NOT_IN_CONTROL,
    RejectReason.WRONG_EPOCH: mav.MAV_RESULT_DENIED,
    RejectReason.EXPIRED: mav.MAV_RESULT_DENIED,
    RejectReason.INVALID: mav.MAV_RESULT_DENIED,
}


class Access(Enum):
    """What a message does, for the signing gate (DESIGN §4.1)."""

    READ = "read"  # asks for information: answered to anyone, signed or not
    ACT = "act"  # changes vehicle state: with a key installed, only from frames signed with it
    KEY = "key"  # SETUP_SIGNING: judges its own signature and always answers why


class Route(NamedTuple):
    """How ``Endpoint.handle`` treats one message type, worked out once per type rather than per frame."""

    handler: str | None  # the Endpoint method's name (looked up on the instance per frame), None: not handled
    target_system: bool  # the message has a target_system field to check
    target_component: bool  # ... and a target_component field
    any_component: bool  # (MANUAL_CONTROL: addressed to the system whatever the component)


class _Sink:
    """The file pymavlink's encoder writes finished frames to."""

    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.frames.append(bytes(data))


@dataclass
class Counters:
    frames: int = 0
    bad_frames: int = 0
    wrong_target: int = 0
    commands: int = 0
    command_retries: int = 0
    unsupported: int = 0
    signing: Counter = field(default_factory=Counter)  # frames per signing Verdict, with a key installed
    handler_faults: int = 0  # a message whose handling raised: reported and counted, never fatal


class Endpoint:
    """MAVLink in, MAVLink out, for one ``Vehicle``."""

    def __init__(self, vehicle: Vehicle, sysid: int = 1, compid: int = 1, origin: Origin | None = None,
                 boot_t: float = 0.0, param_file: Path | None = None, *, key: Key | None = None,
                 keystore: KeyStore | None = None, stamp: Callable[[float], int] = sim_stamp) -> None:
        """``key`` (or ``keystore``, which also keeps the key and the signing timestamp on disk) turns signing on;
        ``stamp(t)`` is the signing clock in 10 µs units since 2015 (the wall clock on a real vehicle)."""
        self.vehicle = vehicle
        self.sysid, self.compid = sysid, compid
        self.origin = origin or Origin()
        self.boot_t = boot_t
        self.param_file = param_file
        self._sink = _Sink()
        self.mav = mav.MAVLink(self._sink, sysid, compid)
        self.parser = mav.MAVLink(None, 0, 0)
        self.parser.robust_parsing = True
        self.counters = Counters()
        self.answered = RetryWindow(RETRY_WINDOW)
        self.notice_at: dict[tuple[int, str], float] = {}
        self.sources: dict[int, Hashable] = {}  # sysid -> where its last frame came from
        self._source: Hashable | None = None
        self.signed: set[int] = set()  # senders whose frames passed the signature check
        self.statustext_id = 0
        self.missions = MissionServer(self._send, self._accept_mission)
        self.telemetry = Telemetry(self.mav, vehicle, self.origin, boot_t,
                                   lambda: (self.counters.frames, self.counters.bad_frames),
                                   lambda: len(self.missions.lists[0]))
        # signing (DESIGN §4.1): None until a key is installed
        self.stamp = stamp
        self.key: Key | None = None
        self.keystore = keystore
        self.streams = Streams()
        self.trusted = True  # the frame being handled is signed with the key, or no key is installed
        self.stamp_saved_at = boot_t
        self.refused_since_notice = 0
        if keystore is not None:
            self.install_key(keystore.key, boot_stamp(keystore.saved_stamp, stamp(boot_t)))
        elif key is not None:
            self.install_key(key, stamp(boot_t))

    # ----- signing ---------------------------------------------------------------------------------------------
    def install_key(self, key: Key, timestamp: int) -> None:
        """Sign everything sent from now on and accept state changes only from frames signed with ``key``."""
        self.key = key
        enable(self.mav, key, timestamp)
        self.vehicle.key_bound = True

    def signing_timestamp(self, t: float) -> int:
        """Our signing timestamp at ``t``: the clock, or further on if we already used (or accepted) later."""
        return advance(self.mav, self.stamp(t)) if self.key is not None else 0

    def save_stamp(self, t: float) -> None:
        """Persist the signing timestamp (every STAMP_SAVE_EVERY s and at shutdown) so a reboot never reuses one."""
        if self.keystore is None or self.key is None:
            return
        self.stamp_saved_at = t
        try:
            self.keystore.save_stamp(self.signing_timestamp(t))
        except OSError as e:
            self.statustext(f"signing timestamp not saved: {e.strerror or e}", mav.MAV_SEVERITY_ERROR)

    def close(self, t: float | None = None) -> None:
        """Shutdown: the last signing timestamp goes to disk."""
        self.save_stamp(self.vehicle.t if t is None else t)

    def _judge(self, m, t: float) -> SignVerdict:
        frame = bytes(m.get_msgbuf())
        self.streams, verdict = self.streams.verify(self.key, frame, self.signing_timestamp(t))
        if verdict is SignVerdict.ACCEPT:
            advance(self.mav, timestamp_of(frame) or 0)  # the spec: continue from the newest timestamp accepted
        self.counters.signing[verdict] += 1
        return verdict

    def _refuse(self, m, verdict: SignVerdict, sender: int, t: float) -> None:
        """A state change that is not signed with the key: dropped, counted, announced at most every few seconds.

        No COMMAND_ACK or MISSION_ACK answers it: a forged frame carrying the owner's sysid would otherwise make the
        vehicle answer the owner's own pending command with a refusal."""
        self.vehicle.commands_rejected += 1
        self.refused_since_notice += 1
        if t - self.notice_at.get((0, "signing"), -math.inf) < REJECT_NOTICE_GAP:
            return
        self.notice_at[(0, "signing")] = t
        more = self.refused_since_notice - 1
        self.refused_since_notice = 0
        self.statustext(f"{verdict.value} {m.get_type()} from {sender} refused"
                        + (f" (+{more} more since the last notice)" if more else ""), mav.MAV_SEVERITY_WARNING)

    # ----- output --------------------------------------------------------------------------------------------
    def _send(self, name: str, **fields) -> None:
        getattr(self.mav, f"{name}_send")(**fields)

    def statustext(self, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        """STATUSTEXT, split into 50-character chunks sharing an id when longer (MAVLink 2 chunking)."""
        raw = text.encode("utf-8", "replace")
        if len(raw) <= 50:
            self.mav.statustext_send(severity, raw)
            return
        self.statustext_id = self.statustext_id % 65535 + 1
        chunks = [raw[i:i + 50] for i in range(0, len(raw), 50)]
        for n, chunk in enumerate(chunks):
            self.mav.statustext_send(severity, chunk, id=self.statustext_id, chunk_seq=n)
        if len(raw) % 50 == 0:
            self.mav.statustext_send(severity, b"", id=self.statustext_id, chunk_seq=len(chunks))

    # ----- input ---------------------------------------------------------------------------------------------
    def receive(self, data: bytes, t: float, source: Hashable | None = None) -> None:
        """Parse and handle whatever frames ``data`` holds; garbage is counted and dropped. ``source`` (a UDP
        address, opaque here) is remembered per sender, so the transport can keep the owner's (``pinned``)."""
        try:
            msgs = read_frames(self.parser, data)
        except Exception:  # noqa: BLE001 - a hostile byte stream must never take the vehicle down
            self.counters.bad_frames += 1
            self.parser = mav.MAVLink(None, 0, 0)
            self.parser.robust_parsing = True
            return
        self._source = source
        try:
            for m in msgs:
                self.handle(m, t)
        finally:
            self._source = None  # frames handled later without a source are not attributed to this one

    def handle(self, m, t: float) -> None:
        """One message: counted, target-checked, signature-judged, then handed to its ``_on_`` method.

        Written for the teleop stream (10 Hz from every station): the type is asked once, the header read once,
        the target fields and the handler's name come from a table per message type (``ROUTES``) instead of
        attribute probes and a name built per frame. The handler itself is still looked up on the instance, so
        replacing a method (as a test does) takes effect."""
        kind = m.get_type()
        if kind == "BAD_DATA":
            self.counters.bad_frames += 1
            return
        header = m.get_header()
        sender = header.srcSystem
        if sender == self.sysid or sender == 0:
            return  # our own frames echoed back, or an anonymous sender
        self.counters.frames += 1
        route = ROUTES.get(kind, NO_ROUTE)
        if not self._for_us(m, route):
            self.counters.wrong_target += 1
            return
        self.trusted = True
        if self.key is not None:
            verdict = self._judge(m, t)
            self.trusted = verdict is SignVerdict.ACCEPT
            if not self.trusted and access(m) is Access.ACT:
                self._refuse(m, verdict, sender, t)
                return
        if self.trusted:  # an unsigned frame never counts as the owner heard: forged heartbeats keep nothing alive
            self.vehicle.heard(sender, t, header.seq)
            if self._source is not None:  # only a trusted frame may move a sender's address (at most 255 senders)
                self.sources[sender] = self._source
                if self.key is not None:
                    self.signed.add(sender)
        if route.handler is None:
            return
        handler = getattr(self, route.handler)
        try:
            handler(m, sender, header.srcComponent, t)
        except (ValueError, TypeError, OverflowError, KeyError) as e:
            # a well-framed message with absurd content: refuse it, keep running, keep state
            self.counters.bad_frames += 1
            self.statustext(f"ignored {kind}: {e}", mav.MAV_SEVERITY_WARNING)
        except Exception as e:  # noqa: BLE001 - a fault in one handler must never take the vehicle down
            self.counters.handler_faults += 1
            self.statustext(f"fault handling {kind}: {type(e).__name__}: {e}", mav.MAV_SEVERITY_ERROR)

    def pinned(self) -> list[Hashable]:
        """Addresses the transport must never drop from its peer table: the owner's and, with a key installed,
        every station signing with it (DESIGN §3.9)."""
        keep = set(self.signed)  # with a key, every station that signs with it (it may become the owner)
        if self.vehicle.book.owner is not None:
            keep.add(self.vehicle.book.owner)
        return [self.sources[s] for s in keep if s in self.sources]

    def _for_us(self, m, route: Route) -> bool:
        if route.target_system:
            ts = m.target_system
            if ts != 0 and ts != self.sysid:
                return False
        if route.target_component:
            tc = m.target_component
            return tc == 0 or tc == self.compid or route.any_component
        return True

    # ----- commands ------------------------------------------------------------------------------------------
    def _on_command_long(self, m, sender: int, scomp: int, t: float) -> None:
        params = (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)
        self._command(m.command, params, sender, scomp, t)

    def _on_command_int(self, m, sender: int, scomp: int, t: float) -> None:
        params = (m.param1, m.param2, m.param3, m.param4, float(m.x), float(m.y), m.z)
        self._command(m.command, params, sender, scomp, t)

    def _command(self, command: int, p: tuple, sender: int, scomp: int, t: float) -> None:
        """Exactly one COMMAND_ACK per command message; a retry or a late copy of any command of the last
        RETRY_WINDOW seconds repeats the first answer and is never executed again (DESIGN §3.9)."""
        key = command_key(sender, scomp, command, p)
        prev = self.answered.seen(key, t)
        if prev is not None:
            self.counters.command_retries += 1
            self._ack(command, prev.result, prev.param2, sender, scomp)
            return
        self.counters.commands += 1
        handler = COMMANDS.get(command)
        bad_param = check_command(command, p) if handler is not None else None
        if handler is None:
            self.counters.unsupported += 1
            result, param2 = mav.MAV_RESULT_UNSUPPORTED, 0
        elif bad_param is not None:  # out of range, NaN or infinite where it matters: never half-executed
            self.statustext(f"refused: {bad_param}", mav.MAV_SEVERITY_WARNING)
            result, param2 = mav.MAV_RESULT_DENIED, 0
        else:
            try:
                result, param2 = handler(self, command_values(command, p), sender, scomp, t)
            except (ValueError, OverflowError) as e:  # NaN or infinity where a number is needed
                self.statustext(f"{command_name(command)} refused: {e}", mav.MAV_SEVERITY_WARNING)
                result, param2 = mav.MAV_RESULT_DENIED, 0
            except Exception as e:  # noqa: BLE001 - answered FAILED, counted, and the vehicle keeps running
                self.counters.handler_faults += 1
                self.statustext(f"fault in {command_name(command)}: {type(e).__name__}: {e}",
                                mav.MAV_SEVERITY_ERROR)
                result, param2 = mav.MAV_RESULT_FAILED, 0
        self.answered.remember(key, result, param2, t)
        self._ack(command, result, param2, sender, scomp)

    def _ack(self, command: int, result: int, param2: int, sender: int, scomp: int) -> None:
        self.mav.command_ack_send(command, result, 0, int(param2), sender, scomp)

    def _verdict(self, chk: Check, what: str, sender: int) -> tuple[int, int]:
        if chk.verdict is Verdict.EXECUTE:
            return mav.MAV_RESULT_ACCEPTED, 0
        if chk.verdict is Verdict.QUEUE:
            return mav.MAV_RESULT_IN_PROGRESS, 0
        self.statustext(f"{what} from {sender} refused: {chk.detail or chk.reason.name}", mav.MAV_SEVERITY_WARNING)
        return REJECT_RESULT.get(chk.reason, mav.MAV_RESULT_DENIED), 0

    def _cmd_arm(self, p, sender, scomp, t):
        chk = self.vehicle.command(sender, scomp, t, ("arm", p[0] >= 0.5))
        return self._verdict(chk, "arm" if p[0] >= 0.5 else "disarm", sender)

    def _cmd_rtl(self, p, sender, scomp, t):
        return self._verdict(self.vehicle.rtl(sender, scomp, t), "return", sender)

    def _cmd_return_to_link(self, p, sender, scomp, t):
        """MAV_CMD_NAV_RETURN_TO_LINK as a command: run this one return block now, keep the stored plan."""
        # _command already checked the parameters against link.plan_items.KINDS and filled NaN with "use the
        # parameter" values (command_values), exactly as an uploaded item is
        item = PlanItem(NAV_RETURN_TO_LINK, *p[:5])
        return self._verdict(self.vehicle.return_now((item,), sender, scomp, t), "return to link", sender)

    def _cmd_set_mode(self, p, sender, scomp, t):
        base, custom, sub = int(p[0]), int(p[1]), int(p[2])
        mode = decode_mode(base, custom, sub)
        return self._mode(mode, sender, scomp, t)

    def _cmd_set_standard_mode(self, p, sender, scomp, t):
        standard = {mav.MAV_STANDARD_MODE_SAFE_RECOVERY: "RTL", mav.MAV_STANDARD_MODE_POSITION_HOLD: "HOLD",
                    mav.MAV_STANDARD_MODE_MISSION: "RTL"}.get(int(p[0]))
        return self._mode(standard, sender, scomp, t)

    def _mode(self, mode: str | None, sender: int, scomp: int, t: float) -> tuple[int, int]:
        if mode is None:
            self.statustext("mode not supported", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        if mode == "RTL":
            return self._cmd_rtl((), sender, scomp, t)
        chk = self.vehicle.take_manual(sender, scomp, t)
        if chk.executes and mode == "HOLD":
            self.vehicle.command(sender, scomp, t, ("hold",))
        return self._verdict(chk, f"mode {mode}", sender)

    def _cmd_request_message(self, p, sender, scomp, t):
        """One message, once: a read, answered to anyone (it starts no stream here)."""
        msgid = int(p[0])
        if msgid == MSG_ID_AVAILABLE_MODES:  # param2: 0 every mode, else the 1-based index of one
            index = _whole(p[1])
            ok = index is not None and self.telemetry.available_modes(index)
            return (mav.MAV_RESULT_ACCEPTED if ok else mav.MAV_RESULT_DENIED), 0
        if not self.telemetry.emit(msgid, t):
            return mav.MAV_RESULT_DENIED, 0
        return mav.MAV_RESULT_ACCEPTED, 0

    def _cmd_autopilot_capabilities(self, p, sender, scomp, t):
        self.telemetry.emit(mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, t)
        return mav.MAV_RESULT_ACCEPTED, 0

    def _cmd_home(self, p, sender, scomp, t):
        self.telemetry.emit(mav.MAVLINK_MSG_ID_HOME_POSITION, t)
        return mav.MAV_RESULT_ACCEPTED, 0

    def _cmd_message_interval(self, p, sender, scomp, t):
        """Telemetry rates are vehicle state shared by every station (DESIGN §3.9): only the owner changes
        them; with nobody owning, any plain client may (MAVSDK and MAVProxy set intervals when they connect)."""
        if self.vehicle.refuses(sender):
            self.statustext(f"message interval from {sender} refused: GCS {self.vehicle.book.owner} is in control",
                            mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        if not self.telemetry.set_interval(int(p[0]), p[1], t):
            return mav.MAV_RESULT_DENIED, 0
        return mav.MAV_RESULT_ACCEPTED, 0

    def _cmd_operator_control(self, p, sender, scomp, t):
        requester = int(p[3]) or sender
        if requester != sender:
            self.statustext("operator control: a station can only request control for itself",
                            mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        if p[0] >= 0.5:
            chk = self.vehicle.acquire(sender, scomp, t, allow_takeover=p[1] >= 0.5)
            if chk.executes:
                return mav.MAV_RESULT_ACCEPTED, self.vehicle.book.epoch or 0
            return self._verdict(chk, "control request", sender)
        return self._verdict(self.vehicle.release(sender, t), "release", sender)

    def _cmd_lease_claim(self, p, sender, scomp, t):
        epoch, index = _whole(p[0]), _whole(p[1])
        if epoch is None or index is None or not 0 <= epoch <= 65535 or not -1 <= index <= 65534:
            self.statustext("lease claim: epoch or index out of range", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        chk = self.vehicle.claim(sender, epoch, index, t)
        if chk.executes and chk.lease is not None:
            return mav.MAV_RESULT_ACCEPTED, chk.lease.index
        return self._verdict(chk, "lease claim", sender)

    def _cmd_lease_expire(self, p, sender, scomp, t):
        epoch, index = _whole(p[0]), _whole(p[1])
        if epoch is None or index is None or not 0 <= epoch <= 65535 or not 0 <= index <= 65534:
            self.statustext("lease expire: epoch or index out of range", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        return self._verdict(self.vehicle.expire(sender, epoch, index, t), "lease expire", sender)

    def _cmd_mission_current(self, p, sender, scomp, t):
        seq = _whole(p[0])
        error = self.vehicle.set_plan_start(seq if seq is not None else -2, sender, scomp, t)
        if error:
            self.statustext(f"set mission current: {error}", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        self.telemetry.emit(mav.MAVLINK_MSG_ID_MISSION_CURRENT, t)
        return mav.MAV_RESULT_ACCEPTED, 0

    # ----- teleop and modes as messages ---------------------------------------------------------------------
    def _on_manual_control(self, m, sender, scomp, t):
        if m.target not in (0, self.sysid):
            self.counters.wrong_target += 1
            return
        x, r = _clamp(m.x, -1000, 1000), _clamp(m.r, -1000, 1000)
        self._teleop(x / 1000 * MAX_TELEOP_SPEED, r / 1000 * MAX_TELEOP_YAW_RATE, sender, scomp, t)

    def _on_set_position_target_local_ned(self, m, sender, scomp, t):
        if m.type_mask & 0b111000 == 0b111000:
            return  # no velocity in this target: only velocity teleop is supported on the ground
        vx, vy = _finite(m.vx), _finite(m.vy)
        yaw_rate = None if m.type_mask & 2048 else _finite(m.yaw_rate)
        if m.coordinate_frame in BODY_FRAMES:
            speed, turn = vx, yaw_rate if yaw_rate is not None else 0.0
        else:
            speed, turn = velocity_to_command(vx, vy, yaw_rate, self.vehicle.estimator.pose.yaw)
        self._teleop(speed, turn, sender, scomp, t)

    def _teleop(self, speed: float, yaw_rate: float, sender: int, scomp: int, t: float) -> None:
        speed = _clamp(speed, -MAX_TELEOP_SPEED, MAX_TELEOP_SPEED)
        yaw_rate = _clamp(yaw_rate, -MAX_TELEOP_YAW_RATE, MAX_TELEOP_YAW_RATE)
        chk = self.vehicle.command(sender, scomp, t, ("teleop", speed, yaw_rate))
        if not chk.executes and chk.verdict is not Verdict.QUEUE:
            key = (sender, "teleop")
            if t - self.notice_at.get(key, -math.inf) >= REJECT_NOTICE_GAP:
                self.notice_at[key] = t
                self.statustext(f"teleop from {sender} refused: {chk.detail or chk.reason.name}",
                                mav.MAV_SEVERITY_WARNING)

    def _on_set_mode(self, m, sender, scomp, t):
        if m.target_system not in (0, self.sysid):
            return
        custom = int(m.custom_mode)
        if custom > 0xFFFF:
            mode = decode_mode(m.base_mode, (custom >> 16) & 0xFF, (custom >> 24) & 0xFF)
        else:
            mode = decode_mode(m.base_mode, custom, 0)
        self._mode(mode, sender, scomp, t)

    def _on_file_transfer_protocol(self, m, sender, scomp, t):
        """Any FTP request gets a NAK (unknown command): ground stations that try FTP first (MAVProxy fetches
        parameters with it) fall back to the parameter protocol at once instead of after their time-out."""
        payload = bytes(m.payload)
        if len(payload) < FTP_HEADER.size:
            return
        seq, session, opcode = FTP_HEADER.unpack_from(payload)[:3]
        if opcode >= 128:
            return  # an ACK or NAK itself: never answer an answer
        nak = FTP_HEADER.pack((seq + 1) & 0xFFFF, session, FTP_OP_NAK, 1, opcode, 0, 0, 0) + bytes(
            [FTP_ERR_UNKNOWN_COMMAND])
        self.mav.file_transfer_protocol_send(0, sender, scomp, nak + bytes(251 - len(nak)))

    # ----- missions -----------------------------------------------------------------------------------------
    def _mission_allowed(self, sender: int, scomp: int, mission_type: int, t: float) -> tuple[int, str]:
        """A return-plan upload is a state change: only the owner (or a plain client auto-granted) may."""
        v = self.vehicle
        v.admit(sender, scomp, t)
        if v.refuses(sender):
            return DENIED, f"mission from {sender} refused: GCS {v.book.owner} is in control"
        return ACCEPTED, ""

    def _accept_mission(self, mission_type: int, items: tuple[Item, ...], sysid: int, compid: int,
                        t: float) -> tuple[int, str]:
        if mission_type != 0:
            return ACCEPTED, ""
        try:
            plan = to_plan(items, self.origin)
        except ItemError as e:  # the field named, answered with its MAV_MISSION_INVALID_PARAMn
            return e.fault.result, str(e)
        except ValueError as e:
            return INVALID, str(e)
        error = self.vehicle.set_plan(plan, t)
        if error:
            return UNSUPPORTED, error
        n = len(self.vehicle.book.plan) if items else 0
        self.statustext(f"return plan: {len(items)} items, {n} leases" if items else "return plan: default")
        return ACCEPTED, ""

    def _on_mission_count(self, m, sender, scomp, t):
        mt = getattr(m, "mission_type", 0)
        why = self.missions.on_count(sender, scomp, m.count, mt, t, self._mission_allowed(sender, scomp, mt, t))
        if why:
            self.statustext(why, mav.MAV_SEVERITY_WARNING)

    def _on_mission_item_int(self, m, sender, scomp, t):
        why = self.missions.on_item(sender, scomp, item_from_message(m), t)
        if why:
            self.statustext(why, mav.MAV_SEVERITY_WARNING)

    def _on_mission_item(self, m, sender, scomp, t):
        """The deprecated float item (MAVProxy still sends it): stored in the MISSION_ITEM_INT form."""
        scale = position_scale(m.frame)
        mt = getattr(m, "mission_type", 0)
        for fld, v in ((5, m.x), (6, m.y)):  # the integer form cannot hold these: refuse them by field
            if not math.isfinite(v) or abs(v * scale) > 2**31 - 1:
                why = self.missions.refuse(sender, m.seq, mt, ItemFault(
                    fld, MISSION_INVALID_PARAM[fld], f"{'xy'[fld - 5]} = {v} is not a position"))
                if why:
                    self.statustext(why, mav.MAV_SEVERITY_WARNING)
                return
        x, y = m.x * scale, m.y * scale
        why = self.missions.on_item(sender, scomp, item_from_message(m, round(x), round(y)), t)
        if why:
            self.statustext(why, mav.MAV_SEVERITY_WARNING)

    def _on_mission_request_list(self, m, sender, scomp, t):
        self.missions.on_request_list(sender, scomp, getattr(m, "mission_type", 0))

    def _on_mission_request_int(self, m, sender, scomp, t):
        self.missions.on_request(sender, scomp, m.seq, getattr(m, "mission_type", 0))

    def _on_mission_request(self, m, sender, scomp, t):
        self.missions.on_request(sender, scomp, m.seq, getattr(m, "mission_type", 0), as_int=False)

    def _on_mission_clear_all(self, m, sender, scomp, t):
        mt = getattr(m, "mission_type", 0)
        why = self.missions.on_clear(sender, scomp, mt, t, self._mission_allowed(sender, scomp, mt, t))
        if why:
            self.statustext(why, mav.MAV_SEVERITY_WARNING)

    def _on_mission_ack(self, m, sender, scomp, t):
        if self.trusted:  # it ends a download for anyone, but only a trusted one may cancel an upload
            self.missions.on_ack(sender, getattr(m, "mission_type", 0))

    # ----- signing ------------------------------------------------------------------------------------------
    def _on_setup_signing(self, m, sender, scomp, t):
        """Key rotation, only over a link already signed with the installed key; answered either way."""
        if self.key is None:
            self.statustext("signing setup refused: no key installed (a key is never installed over the link; "
                            "start the vehicle with --key FILE)", mav.MAV_SEVERITY_WARNING)
            return
        if not self.trusted:
            self.statustext(f"signing setup from {sender} refused: not signed with the installed key",
                            mav.MAV_SEVERITY_WARNING)
            return
        secret = bytes(bytearray(m.secret_key))
        if len(secret) != 32 or not any(secret):
            self.statustext("signing setup refused: signing cannot be switched off over the link",
                            mav.MAV_SEVERITY_WARNING)
            return
        if not 0 <= m.initial_timestamp <= MAX_TIMESTAMP:
            self.statustext("signing setup refused: initial timestamp outside 48 bits", mav.MAV_SEVERITY_WARNING)
            return
        key = Key(secret)
        if self.keystore is not None:
            try:
                self.keystore.save_key(key)
            except OSError as e:
                self.statustext(f"signing setup failed, key kept: cannot save the new key ({e.strerror or e})",
                                mav.MAV_SEVERITY_ERROR)
                return
        self.install_key(key, max(self.signing_timestamp(t), int(m.initial_timestamp)))
        self.save_stamp(t)
        self.statustext(f"signing key changed by GCS {sender} (key id {key.fingerprint})", mav.MAV_SEVERITY_NOTICE)

    def _on_mission_set_current(self, m, sender, scomp, t):
        error = self.vehicle.set_plan_start(m.seq, sender, scomp, t)
        if error:
            self.statustext(f"set mission current: {error}", mav.MAV_SEVERITY_WARNING)
        self.telemetry.emit(mav.MAVLINK_MSG_ID_MISSION_CURRENT, t)

    # ----- parameters ---------------------------------------------------------------------------------------
    def _param_value(self, index: int) -> None:
        spec = SPECS[index]
        self.mav.param_value_send(spec.name.encode(), self.vehicle.params[spec.name], mav.MAV_PARAM_TYPE_REAL32,
                                  len(SPECS), index)

    def _on_param_request_list(self, m, sender, scomp, t):
        for i in range(len(SPECS)):
            self._param_value(i)

    def _on_param_request_read(self, m, sender, scomp, t):
        if m.param_index >= 0:
            if m.param_index < len(SPECS):
                self._param_value(m.param_index)
            return
        name = _param_name(m.param_id)
        names = self.vehicle.params.names()
        if name in names:
            self._param_value(names.index(name))
        else:
            self.statustext(f"no parameter {name!r}", mav.MAV_SEVERITY_WARNING)

    def _on_param_set(self, m, sender, scomp, t):
        name = _param_name(m.param_id)
        names = self.vehicle.params.names()
        if name not in names:
            self.statustext(f"param set refused: no parameter {name!r}", mav.MAV_SEVERITY_WARNING)
            return
        if self.vehicle.refuses(sender):
            self.statustext(f"param set from {sender} refused: GCS {self.vehicle.book.owner} is in control",
                            mav.MAV_SEVERITY_WARNING)
        else:
            try:
                self.vehicle.set_param(name, float(m.param_value))
                if self.param_file is not None:
                    save_parm(self.param_file, self.vehicle.params.values)
            except ParamError as e:
                self.statustext(f"param set refused: {e}", mav.MAV_SEVERITY_WARNING)
            except OSError as e:  # in use until the next boot, which will not know it: say so
                self.statustext(f"param {name} set but not saved: {e.strerror or e}", mav.MAV_SEVERITY_ERROR)
        self._param_value(names.index(name))

    # ----- telemetry ----------------------------------------------------------------------------------------
    def custom_mode(self) -> int:
        return self.telemetry.custom_mode()

    def replies(self) -> list[bytes]:
        """The frames produced since the last call or tick (answers to what was received), without running the
        tick: what a loop serving its link between ticks sends at once."""
        frames = self._sink.frames
        self._sink.frames = []
        return frames

    def _announce(self) -> None:
        v = self.vehicle
        for ev in v.events:
            self.mav.lease_event_send(self.telemetry.boot_ms(ev.t), ev.epoch, wire_index(ev.expired),
                                      wire_index(ev.current),
                                      int(ev.reason), int(ev.holder))
        v.events.clear()
        for text in v.notices:
            self.statustext(text, mav.MAV_SEVERITY_NOTICE)
        v.notices.clear()
        for seq in v.reached:
            if seq >= 0:
                self.mav.mission_item_reached_send(seq)
        v.reached.clear()

    def tick(self, t: float) -> list[bytes]:
        """Announce lease events, send due telemetry, and return every frame produced since the last tick."""
        v = self.vehicle
        if v.events or v.notices or v.reached:  # (rarely: most ticks have nothing to announce)
            self._announce()
        if self.missions.upload is not None:  # (only an upload in progress has a time-out to run)
            why = self.missions.tick(t)
            if why:
                self.statustext(why, mav.MAV_SEVERITY_WARNING)
        if self.key is not None:
            self.signing_timestamp(t)
            if t - self.stamp_saved_at >= STAMP_SAVE_EVERY:
                self.save_stamp(t)
        self.telemetry.tick(t)
        frames = self._sink.frames
        self._sink.frames = []
        return frames


COMMANDS: dict[int, Callable[..., tuple[int, int]]] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: Endpoint._cmd_arm,
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: Endpoint._cmd_rtl,
    mav.MAV_CMD_NAV_RETURN_TO_LINK: Endpoint._cmd_return_to_link,
    mav.MAV_CMD_DO_SET_MODE: Endpoint._cmd_set_mode,
    mav.MAV_CMD_DO_SET_STANDARD_MODE: Endpoint._cmd_set_standard_mode,
    mav.MAV_CMD_REQUEST_MESSAGE: Endpoint._cmd_request_message,
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: Endpoint._cmd_autopilot_capabilities,
    mav.MAV_CMD_GET_HOME_POSITION: Endpoint._cmd_home,
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: Endpoint._cmd_message_interval,
    mav.MAV_CMD_REQUEST_OPERATOR_CONTROL: Endpoint._cmd_operator_control,
    mav.MAV_CMD_LEASE_CLAIM: Endpoint._cmd_lease_claim,
    mav.MAV_CMD_LEASE_EXPIRE: Endpoint._cmd_lease_expire,
    mav.MAV_CMD_DO_SET_MISSION_CURRENT: Endpoint._cmd_mission_current,
}


def _route(cls) -> Route:
    handler = f"_on_{cls.msgname.lower()}"
    return Route(handler if hasattr(Endpoint, handler) else None, "target_system" in cls.fieldnames,
                 "target_component" in cls.fieldnames, cls.msgname == "MANUAL_CONTROL")


# every message of the dialect by type name; anything else (UNKNOWN_n) has no handler and no target fields
ROUTES: dict[str, Route] = {cls.msgname: _route(cls) for cls in mav.mavlink_map.values()}
NO_ROUTE = Route(None, False, False, False)


# The signing gate's one table (DESIGN §4.1): what each message does, messages by name and commands (COMMAND_LONG
# and COMMAND_INT) by id. Anything not listed acts. With a key installed an unsigned station can watch, never act.
ACCESS: dict[str | int, Access] = {
    "HEARTBEAT": Access.READ,  # peer discovery; an unsigned one is never "the owner heard"
    "PARAM_REQUEST_LIST": Access.READ,
    "PARAM_REQUEST_READ": Access.READ,
    "MISSION_REQUEST_LIST": Access.READ,
    "MISSION_REQUEST_INT": Access.READ,
    "MISSION_REQUEST": Access.READ,
    "MISSION_ACK": Access.READ,  # ends a download; cancels an upload only when trusted (_on_mission_ack)
    "SETUP_SIGNING": Access.KEY,
    mav.MAV_CMD_REQUEST_MESSAGE: Access.READ,  # one message, once (a stream is SET_MESSAGE_INTERVAL: acts)
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: Access.READ,
    mav.MAV_CMD_GET_HOME_POSITION: Access.READ,
}


def access(m) -> Access:
    kind = m.get_type()
    if kind in ("COMMAND_LONG", "COMMAND_INT"):
        return ACCESS.get(m.command, Access.ACT)
    return ACCESS.get(kind, Access.ACT)


def _whole(x: float) -> int | None:
    return int(x) if math.isfinite(x) and x == int(x) else None


def _finite(x: float) -> float:
    if not math.isfinite(x):
        raise ValueError("not a finite number")
    return float(x)


def _clamp(x: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, _finite(x)))


def _param_name(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return raw.split("\x00", 1)[0]
