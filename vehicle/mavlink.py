"""The MAVLink endpoint of the vehicle (DESIGN §4): bytes in, bytes out, nothing else.

It parses frames with the generated ``returnlink`` dialect, enforces target ids, maps each standard message or
command onto a ``Vehicle`` method (where the lease rules decide), answers every command exactly once, runs the
mission and parameter protocols, and schedules telemetry. It owns no clock and no socket: ``receive(data, t)``
and ``tick(t) -> [frames]`` are called by whatever loop drives the vehicle.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from link import dialect
from vehicle.app import MAX_TELEOP_SPEED, MAX_TELEOP_YAW_RATE, Vehicle, velocity_to_command
from vehicle.lease import Check, RejectReason, Verdict
from vehicle.missions import (
    ACCEPTED,
    DENIED,
    INVALID,
    UNSUPPORTED,
    Item,
    MissionServer,
    Origin,
    item_from_message,
    position_scale,
    to_plan,
)
from vehicle.modes import decode_mode
from vehicle.params import SPECS, ParamError, format_parm
from vehicle.service import NAV_RETURN_TO_LINK, PlanItem
from vehicle.telemetry import MSG_ID_AVAILABLE_MODES, Telemetry, wire_index

mav = dialect.load()

RETRY_WINDOW = 3.0  # s: an identical command from the same sender within this is a retry, not a new command
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


class _Sink:
    """The file pymavlink's encoder writes finished frames to."""

    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.frames.append(bytes(data))


@dataclass
class _Answered:
    key: tuple
    at: float
    result: int
    param2: int


@dataclass
class Counters:
    frames: int = 0
    bad_frames: int = 0
    wrong_target: int = 0
    commands: int = 0
    command_retries: int = 0
    unsupported: int = 0


class Endpoint:
    """MAVLink in, MAVLink out, for one ``Vehicle``."""

    def __init__(self, vehicle: Vehicle, sysid: int = 1, compid: int = 1, origin: Origin | None = None,
                 boot_t: float = 0.0, param_file: Path | None = None) -> None:
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
        self.answered: dict[tuple[int, int, int], _Answered] = {}
        self.notice_at: dict[tuple[int, str], float] = {}
        self.statustext_id = 0
        self.missions = MissionServer(self._send, self._accept_mission)
        self.telemetry = Telemetry(self.mav, vehicle, self.origin, boot_t,
                                   lambda: (self.counters.frames, self.counters.bad_frames),
                                   lambda: len(self.missions.lists[0]))

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
    def receive(self, data: bytes, t: float) -> None:
        """Parse and handle whatever frames ``data`` holds; garbage is counted and dropped."""
        try:
            msgs = self.parser.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - a hostile byte stream must never take the vehicle down
            self.counters.bad_frames += 1
            self.parser = mav.MAVLink(None, 0, 0)
            self.parser.robust_parsing = True
            return
        for m in msgs:
            self.handle(m, t)

    def handle(self, m, t: float) -> None:
        if m.get_type() == "BAD_DATA":
            self.counters.bad_frames += 1
            return
        sender, scomp = m.get_srcSystem(), m.get_srcComponent()
        if sender == self.sysid or sender == 0:
            return  # our own frames echoed back, or an anonymous sender
        self.counters.frames += 1
        if not self._for_us(m):
            self.counters.wrong_target += 1
            return
        self.vehicle.heard(sender, t, m.get_seq())
        handler = getattr(self, f"_on_{m.get_type().lower()}", None)
        if handler is None:
            return
        try:
            handler(m, sender, scomp, t)
        except (ValueError, TypeError, OverflowError, KeyError) as e:
            # a well-framed message with absurd content: refuse it, keep running, keep state
            self.counters.bad_frames += 1
            self.statustext(f"ignored {m.get_type()}: {e}", mav.MAV_SEVERITY_WARNING)

    def _for_us(self, m) -> bool:
        ts = getattr(m, "target_system", None)
        if ts is not None and ts not in (0, self.sysid):
            return False
        tc = getattr(m, "target_component", None)
        return tc is None or tc in (0, self.compid) or m.get_type() == "MANUAL_CONTROL"

    # ----- commands ------------------------------------------------------------------------------------------
    def _on_command_long(self, m, sender: int, scomp: int, t: float) -> None:
        params = (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)
        self._command(m.command, params, sender, scomp, t)

    def _on_command_int(self, m, sender: int, scomp: int, t: float) -> None:
        params = (m.param1, m.param2, m.param3, m.param4, float(m.x), float(m.y), m.z)
        self._command(m.command, params, sender, scomp, t)

    def _command(self, command: int, p: tuple, sender: int, scomp: int, t: float) -> None:
        """Exactly one COMMAND_ACK per command message; a retry repeats the first answer without re-executing."""
        key = (command, *[round(x, 6) if math.isfinite(x) else str(x) for x in p])
        slot = (sender, scomp, command)
        prev = self.answered.get(slot)
        if prev is not None and prev.key == key and t - prev.at <= RETRY_WINDOW:
            self.counters.command_retries += 1
            prev.at = t
            self._ack(command, prev.result, prev.param2, sender, scomp)
            return
        self.counters.commands += 1
        handler = COMMANDS.get(command)
        if handler is None:
            self.counters.unsupported += 1
            result, param2 = mav.MAV_RESULT_UNSUPPORTED, 0
        else:
            try:
                result, param2 = handler(self, p, sender, scomp, t)
            except (ValueError, OverflowError) as e:  # NaN or infinity where a number is needed
                self.statustext(f"command {command} refused: {e}", mav.MAV_SEVERITY_WARNING)
                result, param2 = mav.MAV_RESULT_DENIED, 0
        self.answered[slot] = _Answered(key, t, result, param2)
        if len(self.answered) > 256:
            for k in sorted(self.answered, key=lambda k: self.answered[k].at)[:128]:
                del self.answered[k]
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
        item = PlanItem(NAV_RETURN_TO_LINK, *[0.0 if math.isnan(x) else x for x in p[:4]])
        if not (0 <= item.param1 <= 10000 and 0 <= item.param2 <= 5 and -1 <= item.param3 <= 2
                and -1 <= item.param4 <= 1):
            self.statustext("return to link: parameter out of range", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
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
        if m.coordinate_frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_FRD):
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
        x, y = _finite(m.x) * scale, _finite(m.y) * scale
        if abs(x) > 2**31 - 1 or abs(y) > 2**31 - 1:
            raise ValueError("position out of range")
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
        self.missions.on_ack(sender, getattr(m, "mission_type", 0))

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
                    self.param_file.write_text(format_parm(self.vehicle.params.values), encoding="utf-8")
            except ParamError as e:
                self.statustext(f"param set refused: {e}", mav.MAV_SEVERITY_WARNING)
        self._param_value(names.index(name))

    # ----- telemetry ----------------------------------------------------------------------------------------
    def custom_mode(self) -> int:
        return self.telemetry.custom_mode()

    def tick(self, t: float) -> list[bytes]:
        """Announce lease events, send due telemetry, and return every frame produced since the last tick."""
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
        why = self.missions.tick(t)
        if why:
            self.statustext(why, mav.MAV_SEVERITY_WARNING)
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
