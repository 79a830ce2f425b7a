"""A ground station for returnlink vehicles, on pymavlink, with no clock and no socket of its own.

``GroundStation`` takes bytes with ``feed(data, t)`` and returns frames to send from ``tick(t)``: its 1 Hz GCS
heartbeat, command retries, mission transfers and a steady teleop stream. The lockstep simulator drives it with
simulated time; ``gcs.client.Client`` drives it over UDP with the wall clock and adds blocking waits.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from gcs.file_transfer import Download, FileClient
from gcs.mission_transfer import MissionClient, Transfer
from link import dialect
from link.codec import read_datagram
from link.mission import Item
from link.modes import PX4_AUTO, PX4_AUTO_LOITER
from link.setpoints import VELOCITY, VELOCITY_YAW_RATE
from link.signing import Key, SigningVerdict, Streams, advance, enable, sim_stamp
from link.wire import MAVLINK_VERSION, NO_INDEX

mav = dialect.load()

COMMAND_RETRY = 1.0  # s between retries of an unanswered command
COMMAND_TRIES = 4
TELEOP_PERIOD = 0.1  # s: teleop is streamed at 10 Hz
STOPPED = ("velocity", 0.0, 0.0, math.nan)  # the teleop stream of a station holding still (zero velocity)
# the dialect's message types that carry a target_system, by name: most of the vehicle's telemetry does not, and
# asking each of those frames for the field would cost a failed attribute lookup per frame
TARGETED = frozenset(cls.msgname for cls in mav.mavlink_map.values() if "target_system" in cls.fieldnames)


@dataclass(frozen=True)
class LeaseStatus:
    """LEASE_STATUS as a typed value."""

    t: float
    epoch: int
    owner: int
    current: int
    sublease: int
    holder: int
    claimed: bool
    scheduled: int
    state: int
    last_reason: int
    link_age: float | None
    return_start: tuple[float, float] | None
    return_target: tuple[float, float] | None
    displacement: float
    max_displacement: float
    route_remaining: float
    trail_points: int

    @property
    def state_name(self) -> str:
        return mav.enums["RETURNLINK_STATE"][self.state].name.removeprefix("RETURNLINK_STATE_")

    @property
    def reason_name(self) -> str:
        return mav.enums["LEASE_EXPIRE_REASON"][self.last_reason].name.removeprefix("LEASE_EXPIRE_REASON_")


@dataclass(frozen=True)
class LeaseEventRecord:
    t: float
    epoch: int
    expired: int | None
    current: int | None
    reason: str
    holder: str


@dataclass
class Pending:
    """One command in flight: resent until answered or out of tries."""

    command: int
    params: tuple[float, ...]
    sent_at: float
    tries: int = 1
    result: int | None = None
    param2: int = 0
    done: bool = False

    @property
    def ok(self) -> bool:
        return self.result in (mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_IN_PROGRESS)

    @property
    def result_name(self) -> str:
        if self.result is None:
            return "NO_ANSWER"
        entry = mav.enums["MAV_RESULT"].get(self.result)
        return entry.name if entry else str(self.result)


@dataclass
class VehicleView:
    """What the station knows of the vehicle it talks to (the vehicle itself is ``vehicle.app.Vehicle``)."""

    sysid: int = 0
    compid: int = 0
    last_heard: float | None = None
    mav_type: int = 0
    custom_mode: int = 0
    armed: bool = False
    position: tuple[float, float] | None = None
    yaw: float = 0.0
    status: LeaseStatus | None = None
    control_owner: int | None = None
    params: dict[str, float] = field(default_factory=dict)
    param_count: int = 0
    radio_rssi: int | None = None


class GroundStation:
    def __init__(self, sysid: int = 255, compid: int = 190, target: int = 1, target_comp: int = 1,
                 key: Key | None = None, link_id: int = 0, stamp: Callable[[float], int] = sim_stamp) -> None:
        """With ``key`` every frame sent is signed (docs/architecture.md §4.1) and only the vehicle's frames signed
        with the same key are believed; ``stamp(t)`` is the signing clock (the wall clock for a real station)."""
        self.sysid, self.compid = sysid, compid
        self.target, self.target_comp = target, target_comp
        self.frames: list[bytes] = []
        self.mav = mav.MAVLink(self, sysid, compid)
        self.key, self.stamp = key, stamp
        self.streams = Streams()
        self.refused: Counter = Counter()  # the vehicle's frames not believed, per SigningVerdict
        if key is not None:
            enable(self.mav, key, stamp(0.0), link_id)
        self.parser = mav.MAVLink(None, 0, 0)
        self.parser.robust_parsing = True
        self.vehicle = VehicleView()
        self.pending: dict[int, Pending] = {}
        # no later than the oldest send of a command still unanswered (inf: none): until COMMAND_RETRY after it,
        # no retry can be due, and the tick need not walk every command ever sent
        self._oldest_unanswered = math.inf
        self.missions = MissionClient(self.mav, target, target_comp)  # the mission protocol's ground side
        self.files = FileClient(self.mav, target, target_comp)  # MAVLink FTP's ground side (reads only)
        self.events: list[LeaseEventRecord] = []
        self.texts: list[tuple[float, str]] = []
        self._chunks: dict[int, dict[int, bytes]] = {}
        self.acks: list[tuple[float, int, int]] = []  # (t, command, result): every COMMAND_ACK received
        self.next_heartbeat = 0.0
        self.teleop: tuple[str, float, float, float] | None = None  # (kind, a, b, c) streamed at 10 Hz
        self.next_teleop = 0.0
        self.listeners: list[Callable[[object, float], None]] = []
        self.t = 0.0

    # pymavlink writes encoded frames here
    def write(self, data: bytes) -> None:
        self.frames.append(bytes(data))

    # ----- the loop ------------------------------------------------------------------------------------------
    def feed(self, data: bytes, t: float) -> None:
        self.t = t
        try:
            msgs = read_datagram(self.parser, data)
        except Exception:  # noqa: BLE001 - a garbled frame must not stop the station
            self.parser = mav.MAVLink(None, 0, 0)
            self.parser.robust_parsing = True
            return
        for m in msgs:
            self._handle(m, t)

    def tick(self, t: float) -> list[bytes]:
        self.t = t
        if self.key is not None:
            advance(self.mav, self.stamp(t))
        if t >= self.next_heartbeat:
            self.next_heartbeat = t + 1.0
            self.mav.send(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0,
                                                        mav.MAV_STATE_ACTIVE, MAVLINK_VERSION))
        if t - self._oldest_unanswered >= COMMAND_RETRY:
            for p in self.pending.values():
                if not p.done and t - p.sent_at >= COMMAND_RETRY:
                    if p.tries >= COMMAND_TRIES:
                        p.done = True
                    else:
                        p.tries += 1
                        p.sent_at = t
                        self._send_command(p, confirmation=p.tries - 1)
            self._oldest_unanswered = min((p.sent_at for p in self.pending.values() if not p.done), default=math.inf)
        self.missions.tick(t)
        self.files.tick(t)
        if self.teleop is not None and t >= self.next_teleop:
            self.next_teleop = t + TELEOP_PERIOD
            self._send_teleop()
        if not self.frames:  # most ticks send nothing
            return []
        out, self.frames = self.frames, []
        return out

    # ----- commands ------------------------------------------------------------------------------------------
    def command(self, command: int, *params: float) -> Pending:
        p7 = tuple(params) + (0.0,) * (7 - len(params))
        p = Pending(command, p7, self.t)
        self.pending[command] = p
        self._oldest_unanswered = min(self._oldest_unanswered, p.sent_at)
        self._send_command(p, 0)
        return p

    def _send_command(self, p: Pending, confirmation: int) -> None:
        self.mav.command_long_send(self.target, self.target_comp, p.command, confirmation, *p.params)

    def acquire(self, allow_takeover: bool = False) -> Pending:
        return self.command(mav.MAV_CMD_REQUEST_OPERATOR_CONTROL, 1, float(allow_takeover), 10, 0)

    def release(self) -> Pending:
        return self.command(mav.MAV_CMD_REQUEST_OPERATOR_CONTROL, 0, 0, 10, 0)

    def claim(self, index: int = -1) -> Pending:
        st = self.vehicle.status
        return self.command(mav.MAV_CMD_LEASE_CLAIM, st.epoch if st else 0, index)

    def expire(self, index: int | None = None) -> Pending:
        st = self.vehicle.status
        return self.command(mav.MAV_CMD_LEASE_EXPIRE, st.epoch if st else 0,
                            st.current if index is None and st else (index or 0))

    def rtl(self) -> Pending:
        return self.command(mav.MAV_CMD_NAV_RETURN_TO_LAUNCH)

    def hold(self) -> Pending:
        self.teleop = None
        return self.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4_AUTO, PX4_AUTO_LOITER)

    def arm(self, armed: bool = True) -> Pending:
        return self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, float(armed))

    # ----- teleop --------------------------------------------------------------------------------------------
    def drive_velocity(self, vn: float, ve: float, yaw_rate: float | None = None) -> None:
        """Stream a NED velocity target at 10 Hz until ``stop`` (SET_POSITION_TARGET_LOCAL_NED)."""
        self.teleop = ("velocity", vn, ve, math.nan if yaw_rate is None else yaw_rate)

    def drive_manual(self, x: float, r: float) -> None:
        """Stream MANUAL_CONTROL (x forward, r yaw, each -1..1) at 10 Hz until ``stop``."""
        self.teleop = ("manual", x, r, 0.0)

    def stop(self) -> None:
        self.teleop = STOPPED

    def stop_streaming(self) -> None:
        self.teleop = None

    def _send_teleop(self) -> None:
        assert self.teleop is not None
        kind, a, b, c = self.teleop
        if kind == "manual":
            self.mav.manual_control_send(self.target, int(a * 1000), 0, 500, int(b * 1000), 0)
        else:
            mask = VELOCITY if math.isnan(c) else VELOCITY_YAW_RATE
            self.mav.set_position_target_local_ned_send(
                0, self.target, self.target_comp, mav.MAV_FRAME_LOCAL_NED, mask, 0, 0, 0, a, b, 0, 0, 0, 0, 0,
                0.0 if math.isnan(c) else c)

    # ----- parameters ----------------------------------------------------------------------------------------
    def param_request_all(self) -> None:
        self.mav.param_request_list_send(self.target, self.target_comp)

    def param_request(self, name: str) -> None:
        self.mav.param_request_read_send(self.target, self.target_comp, name.encode(), -1)

    def param_set(self, name: str, value: float) -> None:
        self.mav.param_set_send(self.target, self.target_comp, name.encode(), float(value),
                                mav.MAV_PARAM_TYPE_REAL32)

    # ----- signing -------------------------------------------------------------------------------------------
    def rotate_key(self, new: Key) -> None:
        """SETUP_SIGNING signed with the current key, then sign with ``new`` (the vehicle answers with its new key).

        A vehicle takes a new key only over a link already signed with its installed one (docs/architecture.md §4.1)."""
        if self.key is None:
            raise ValueError("key rotation needs the vehicle's current key")
        ts = advance(self.mav, self.stamp(self.t))
        self.mav.setup_signing_send(self.target, self.target_comp, list(new.secret), ts)
        self.key = new
        enable(self.mav, new, ts + 1, self.mav.signing.link_id)

    # ----- files (gcs/file_transfer.py) ---------------------------------------------------------------------
    def fetch(self, path: str) -> Download:
        """Start downloading the vehicle's file ``path`` over MAVLink FTP (``linkmap.csv``: its link map)."""
        return self.files.get(path, self.t)

    # ----- missions (gcs/mission_transfer.py) ---------------------------------------------------------------
    @property
    def transfer(self) -> Transfer | None:
        """The mission transfer in progress or last finished (None: none yet, or abandoned)."""
        return self.missions.transfer

    @transfer.setter
    def transfer(self, value: Transfer | None) -> None:
        self.missions.transfer = value

    def upload(self, items: list[Item], mission_type: int = 0) -> Transfer:
        return self.missions.upload(items, mission_type, self.t)

    def download(self, mission_type: int = 0) -> Transfer:
        return self.missions.download(mission_type, self.t)

    def clear(self, mission_type: int = 0) -> Transfer:
        return self.missions.clear(mission_type, self.t)

    # ----- incoming ------------------------------------------------------------------------------------------
    def _handle(self, m, t: float) -> None:
        kind = m.get_type()
        if kind == "BAD_DATA":
            return
        if kind == "RADIO_STATUS":
            self.vehicle.radio_rssi = m.rssi
            return
        if m.get_srcSystem() != self.target:
            return
        if self.key is not None:
            own = advance(self.mav, self.stamp(t))
            self.streams, verdict = self.streams.verify(self.key, bytes(m.get_msgbuf()), own)
            if verdict is not SigningVerdict.ACCEPT:
                self.refused[verdict] += 1  # a forged ACK or status must not be believed
                return
        self.vehicle.last_heard = t
        if kind in TARGETED and m.target_system != 0 and m.target_system != self.sysid:
            return  # addressed to another station
        name = kind.lower()
        handler = (getattr(self, f"_on_{name}", None) or getattr(self.missions, f"on_{name}", None)
                   or getattr(self.files, f"on_{name}", None))
        if handler is not None:
            handler(m, t)
        for fn in self.listeners:
            fn(m, t)

    def _on_heartbeat(self, m, t: float) -> None:
        v = self.vehicle
        v.sysid, v.compid = m.get_srcSystem(), m.get_srcComponent()
        v.mav_type, v.custom_mode = m.type, m.custom_mode
        v.armed = bool(m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)

    def _on_local_position_ned(self, m, t: float) -> None:
        self.vehicle.position = (m.x, m.y)

    def _on_attitude(self, m, t: float) -> None:
        self.vehicle.yaw = m.yaw

    def _on_lease_status(self, m, t: float) -> None:
        def pair(a: float, b: float) -> tuple[float, float] | None:
            return None if math.isnan(a) or math.isnan(b) else (a, b)

        self.vehicle.status = LeaseStatus(
            t, m.epoch, m.owner_sysid, m.current_index, m.sublease, m.holder, bool(m.claimed), m.scheduled_count,
            m.state, m.last_expire_reason, None if m.link_age_ms == 0xFFFFFFFF else m.link_age_ms / 1000,
            pair(m.return_start_n, m.return_start_e), pair(m.return_target_n, m.return_target_e), m.displacement,
            m.max_displacement, m.route_remaining, m.trail_points)

    def _on_lease_event(self, m, t: float) -> None:
        reason = mav.enums["LEASE_EXPIRE_REASON"].get(m.reason)
        holder = mav.enums["LEASE_HOLDER"].get(m.holder)
        self.events.append(LeaseEventRecord(
            t, m.epoch, None if m.expired_index == NO_INDEX else m.expired_index,
            None if m.current_index == NO_INDEX else m.current_index,
            reason.name.removeprefix("LEASE_EXPIRE_REASON_") if reason else str(m.reason),
            holder.name.removeprefix("LEASE_HOLDER_") if holder else str(m.holder)))

    def _on_control_status(self, m, t: float) -> None:
        self.vehicle.control_owner = m.gcs_main or None

    def _on_statustext(self, m, t: float) -> None:
        text = m.text if isinstance(m.text, bytes) else m.text.encode()
        text = text.split(b"\x00", 1)[0]
        if not m.id:
            self.texts.append((t, text.decode("utf-8", "replace")))
            return
        parts = self._chunks.setdefault(m.id, {})
        parts[m.chunk_seq] = text
        if len(text) < 50:
            chunks = self._chunks.pop(m.id)
            whole = all(k in chunks for k in range(m.chunk_seq + 1))
            joined = b"".join(chunks[k] for k in sorted(chunks)).decode("utf-8", "replace")
            self.texts.append((t, joined if whole else "..." + joined))  # '...': a chunk was lost

    def _on_command_ack(self, m, t: float) -> None:
        self.acks.append((t, m.command, m.result))
        p = self.pending.get(m.command)
        if p is not None and not p.done:
            p.result, p.param2, p.done = m.result, m.result_param2, True

    def _on_param_value(self, m, t: float) -> None:
        name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode("ascii", "replace")
        self.vehicle.params[name.split("\x00", 1)[0]] = float(m.param_value)
        self.vehicle.param_count = m.param_count
