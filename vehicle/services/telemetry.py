"""What the vehicle reports and when (docs/architecture.md §4 telemetry): the heartbeat, position and attitude, health,
home, mission progress, operator control and lease status, each at its own rate, some also on change; and the
commands that ask for telemetry (REQUEST_MESSAGE, GET_HOME_POSITION, REQUEST_AUTOPILOT_CAPABILITIES) or change its
rates (SET_MESSAGE_INTERVAL, a state change only the owner may make).

Everything reported is read from the vehicle's status snapshot (``vehicle.port.Status``), one per tick. Positions
come from the estimator, never from ground truth, because that is all a real vehicle knows. A companion
computer composes the same service with its own identity (``mav_type``, ``autopilot``) and only the streams it
owns (``rates``): its autopilot reports position and attitude itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from link.mission import Origin
from link.wire import NO_INDEX
from vehicle import modes
from vehicle.lease import Holder
from vehicle.lease_terms import State
from vehicle.port import Status, VehiclePort
from vehicle.services.base import Outbox, Reply, Service, Source, boot_ms, command, mav, whole, wire_index
from vehicle.services.heartbeat import MSG_ID_AVAILABLE_MODES, MSG_ID_CURRENT_MODE, Heartbeat

HEALTH_SENSORS = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                  | mav.MAV_SYS_STATUS_SENSOR_3D_MAG | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
                  | mav.MAV_SYS_STATUS_PREARM_CHECK)
CAPABILITIES = (mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mav.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
                | mav.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
                | mav.MAV_PROTOCOL_CAPABILITY_COMPONENT_ACCEPTS_GCS_CONTROL
                | mav.MAV_PROTOCOL_CAPABILITY_FTP)  # reads only (vehicle/services/ftp.py)

HEARTBEAT_PERIOD = 1.0  # s
# default telemetry intervals, s (changed with SET_MESSAGE_INTERVAL)
DEFAULT_RATES = {
    mav.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.25,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.25,
    mav.MAVLINK_MSG_ID_ATTITUDE: 0.25,
    mav.MAVLINK_MSG_ID_HOME_POSITION: 5.0,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    mav.MAVLINK_MSG_ID_CONTROL_STATUS: 1.0,
    mav.MAVLINK_MSG_ID_LEASE_STATUS: 0.5,
}


class Telemetry(Service):
    """Scheduled and on-change reports of one component, through its outbox.

    Each builder constructs pymavlink's message object and hands it to the encoder's ``send``, which is what the
    generated ``<name>_send`` methods do after ``<name>_encode`` (the defaults are the same:
    tests/test_telemetry_builders.py). ``rates`` are the streams sent unasked and their default intervals."""

    def __init__(self, out: Outbox, vehicle: VehiclePort, origin: Origin, boot_t: float,
                 link_stats: Callable[[], tuple[int, int]], mission_count: Callable[[], int], *,
                 mav_type: int | None = None, autopilot: int = mav.MAV_AUTOPILOT_GENERIC,
                 rates: Mapping[int, float] = DEFAULT_RATES) -> None:
        self.out = out
        self.mav = out.mav
        self.vehicle = vehicle
        self.origin = origin
        self.boot_t = boot_t
        self.link_stats = link_stats  # (frames received, bad frames) for SYS_STATUS
        self.mission_count = mission_count
        self.heartbeat = Heartbeat(out.mav, vehicle, mav_type, autopilot)
        self.rates = dict(rates)
        self.intervals = dict(rates)
        self.due: dict[int, float] = {}
        self.next_due = boot_t  # earliest of ``due``: most ticks have nothing scheduled
        self.next_heartbeat = boot_t
        self.last_status_key: tuple | None = None
        self.last_control_key: tuple | None = None
        self.last_mode: int | None = None

    def boot_ms(self, t: float) -> int:
        return boot_ms(t, self.boot_t)

    # ----- the telemetry commands ----------------------------------------------------------------------------
    @command(mav.MAV_CMD_REQUEST_MESSAGE)
    def _request_message(self, p: tuple, src: Source, t: float) -> Reply:
        """One message, once: a read, answered to anyone (it starts no stream here)."""
        msgid = int(p[0])
        if msgid == MSG_ID_AVAILABLE_MODES:  # param2: 0 every mode, else the 1-based index of one
            index = whole(p[1])
            ok = index is not None and self.heartbeat.available_modes(index)
            return (mav.MAV_RESULT_ACCEPTED if ok else mav.MAV_RESULT_DENIED), 0
        return (mav.MAV_RESULT_ACCEPTED if self.emit(msgid, t) else mav.MAV_RESULT_DENIED), 0

    @command(mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES)
    def _capabilities(self, p: tuple, src: Source, t: float) -> Reply:
        self.emit(mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, t)
        return mav.MAV_RESULT_ACCEPTED, 0

    @command(mav.MAV_CMD_GET_HOME_POSITION)
    def _home_position(self, p: tuple, src: Source, t: float) -> Reply:
        self.emit(mav.MAVLINK_MSG_ID_HOME_POSITION, t)
        return mav.MAV_RESULT_ACCEPTED, 0

    @command(mav.MAV_CMD_SET_MESSAGE_INTERVAL)
    def _message_interval(self, p: tuple, src: Source, t: float) -> Reply:
        """Telemetry rates are vehicle state shared by every station (docs/architecture.md §3.9): only the owner changes
        them; with nobody owning, any plain client may (MAVSDK and MAVProxy set intervals when they connect)."""
        v = self.vehicle
        if v.refuses(src.sysid):
            self.out.statustext(f"message interval from {src.sysid} refused: GCS {v.status().book.owner} is in control",
                                mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        return (mav.MAV_RESULT_ACCEPTED if self.set_interval(int(p[0]), p[1], t) else mav.MAV_RESULT_DENIED), 0

    def set_interval(self, msgid: int, interval_us: float, t: float) -> bool:
        """SET_MESSAGE_INTERVAL: -1 off, 0 default, else microseconds. False for what is not telemetry here."""
        if msgid not in BUILDERS or msgid == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return False
        if interval_us == -1:  # off: nothing more of it, not even the one a new rate sends at once
            self.intervals[msgid] = self.due[msgid] = math.inf
            return True
        if interval_us == 0:
            self.intervals[msgid] = self.rates.get(msgid, math.inf)
        elif interval_us > 0:
            self.intervals[msgid] = max(0.02, interval_us / 1e6)
        else:
            return False
        self.due[msgid] = t
        self.next_due = min(self.next_due, t)
        return True

    def tick(self, t: float) -> None:
        s = self.vehicle.status()
        if t >= self.next_heartbeat:
            self.next_heartbeat = t + HEARTBEAT_PERIOD
            self.heartbeat.send(t)
        self._on_change(t, s)
        if t + 1e-9 < self.next_due:
            return
        # one pass: what is due is sent, and the earliest next due time is found on the way (the builders send
        # frames, they never reschedule a stream)
        next_due = math.inf
        dues = self.due
        for msgid, interval in self.intervals.items():
            due = dues.get(msgid, self.boot_t)
            if t + 1e-9 >= due:
                # keep the average rate exact although ticks are coarser than the interval
                nxt = due + interval
                due = dues[msgid] = nxt if nxt > t else t + interval
                BUILDERS[msgid](self, t)  # (every stream here has a builder: set_interval sees to it)
            if due < next_due:
                next_due = due
        self.next_due = next_due

    def _on_change(self, t: float, s: Status) -> None:
        """LEASE_STATUS, MISSION_CURRENT and CONTROL_STATUS due now, and CURRENT_MODE sent, if what they show
        changed. (Computed every tick, plainly: the two memos that skipped it while the book, the block and the hold
        were the very same objects saved 1.1 us of a 66 us tick, under the 5 % a speed idiom must buy, issue 29.)"""
        b = s.book
        status_key = self._status_key(s)
        if status_key != self.last_status_key:
            self.last_status_key = status_key
            self.due[mav.MAVLINK_MSG_ID_LEASE_STATUS] = t
            self.due[mav.MAVLINK_MSG_ID_MISSION_CURRENT] = t
            self.next_due = t
        mode = modes.custom_mode(status_key[-1], s.holding)  # teleop or hold can change it with no lease change
        if mode != self.last_mode:
            self.last_mode = mode
            self._current_mode(t)
        control_key = (b.owner, b.takeover_allowed)
        if control_key != self.last_control_key:
            self.last_control_key = control_key
            self.due[mav.MAVLINK_MSG_ID_CONTROL_STATUS] = t
            self.next_due = t

    @staticmethod
    def _status_key(s: Status) -> tuple:
        b = s.book
        cur = b.current
        return (b.epoch, b.owner, cur.index if cur else None, cur.newest_sub if cur else None,
                cur.claimed if cur else None, s.state)

    def emit(self, msgid: int, t: float) -> bool:
        build = BUILDERS.get(msgid)
        if build is None:
            return False
        build(self, t)
        return True

    def custom_mode(self) -> int:
        return self.heartbeat.custom_mode()

    def _heartbeat(self, t: float) -> None:
        self.heartbeat.send(t)

    def _sys_status(self, t: float) -> None:
        s = self.vehicle.status()
        gps_ok = s.sensing and s.fixes_used > 0 and self._fix_age(s, t) < 3.0
        present = HEALTH_SENSORS | mav.MAV_SYS_STATUS_SENSOR_GPS
        # no geofence here, and none breached: the health bit is set as ArduPilot does, or MAVProxy announces
        # "fence breach" on the first SYS_STATUS
        health = HEALTH_SENSORS | mav.MAV_SYS_STATUS_GEOFENCE | (mav.MAV_SYS_STATUS_SENSOR_GPS if gps_ok else 0)
        frames, bad = self.link_stats()
        drop = int(min(10000, 10000 * bad / max(1, frames + bad)))
        self.mav.send(mav.MAVLink_sys_status_message(present, present, health, 200, 24000, 1000, 90, drop,
                                                     min(bad, 65535), 0, 0, 0, 0))

    @staticmethod
    def _fix_age(s: Status, t: float) -> float:
        last = s.last_fix_t
        return math.inf if last is None else t - last

    def _position(self, t: float) -> None:
        s = self.vehicle.status()
        p = s.pose
        lat, lon = self.origin.to_global(p.x, p.y)
        vx, vy = self._velocity(s.speed, p.yaw)
        hdg = int(math.degrees(p.yaw) % 360 * 100)
        self.mav.send(mav.MAVLink_global_position_int_message(
            self.boot_ms(t), int(lat * 1e7), int(lon * 1e7), int(self.origin.alt * 1000), 0, int(vx * 100),
            int(vy * 100), 0, hdg))

    @staticmethod
    def _velocity(speed: float, yaw: float) -> tuple[float, float]:
        """``speed`` over the ground at heading ``yaw`` (the pose's, which the caller already holds)."""
        return speed * math.cos(yaw), speed * math.sin(yaw)

    def _local_position(self, t: float) -> None:
        s = self.vehicle.status()
        p = s.pose
        vx, vy = self._velocity(s.speed, p.yaw)
        self.mav.send(mav.MAVLink_local_position_ned_message(self.boot_ms(t), p.x, p.y, 0.0, vx, vy, 0.0))

    def _attitude(self, t: float) -> None:
        s = self.vehicle.status()
        self.mav.send(mav.MAVLink_attitude_message(self.boot_ms(t), 0.0, 0.0, s.pose.yaw, 0.0, 0.0, s.yaw_rate))

    def _gps_raw(self, t: float) -> None:
        s = self.vehicle.status()
        fix_std = s.fix_std
        last = s.last_fix
        fresh = last is not None and self._fix_age(s, t) < 3.0
        lat, lon = self.origin.to_global(*(last if fresh else (0.0, 0.0)))
        eph = int(min(65535, (fix_std if fix_std is not None else 0.7) * 100)) if fresh else 65535
        self.mav.send(mav.MAVLink_gps_raw_int_message(
            int(t * 1e6), 3 if fresh else 1, int(lat * 1e7) if fresh else 0, int(lon * 1e7) if fresh else 0,
            int(self.origin.alt * 1000) if fresh else 0, eph, 65535, 65535, 65535, 10 if fresh else 0))

    def _extended_sys_state(self, t: float) -> None:
        self.mav.send(mav.MAVLink_extended_sys_state_message(mav.MAV_VTOL_STATE_UNDEFINED,
                                                             mav.MAV_LANDED_STATE_ON_GROUND))

    def _home(self, t: float) -> None:
        hx, hy = self.vehicle.status().home
        lat, lon = self.origin.to_global(hx, hy)
        self.mav.send(mav.MAVLink_home_position_message(int(lat * 1e7), int(lon * 1e7), int(self.origin.alt * 1000),
                                                        hx, hy, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                                                        int(t * 1e6)))

    def _autopilot_version(self, t: float) -> None:
        self.mav.send(mav.MAVLink_autopilot_version_message(CAPABILITIES, 0x00010000 | 0xFF, 0, 0, 0, [0] * 8, [0] * 8,
                                                            [0] * 8, 0, 0, self.mav.srcSystem))

    def _mission_current(self, t: float) -> None:
        s = self.vehicle.status()
        total = self.mission_count()
        st = s.block
        seq = st.items[st.item].seq if st is not None and 0 <= st.item < len(st.items) else 0
        state = mav.MISSION_STATE_ACTIVE if s.state in (State.RETURNING, State.HOLDING, State.NAVIGATING) \
            else (mav.MISSION_STATE_NOT_STARTED if total else mav.MISSION_STATE_NO_MISSION)
        self.mav.send(mav.MAVLink_mission_current_message(max(0, seq), total, state))

    def _current_mode(self, t: float) -> None:
        self.heartbeat.current_mode(t)

    def _control_status(self, t: float) -> None:
        b = self.vehicle.status().book
        flags = mav.GCS_CONTROL_STATUS_FLAGS_SYSTEM_MANAGER
        if b.takeover_allowed:
            flags |= mav.GCS_CONTROL_STATUS_FLAGS_TAKEOVER_ALLOWED
        self.mav.send(mav.MAVLink_control_status_message(flags, b.owner or 0, [0] * 10))

    def _lease_status(self, t: float) -> None:
        s = self.vehicle.status()
        b = s.book
        cur = b.current
        age = b.link.age(t)
        st = s.block
        nan = math.nan
        start = st.start if st is not None else (nan, nan)
        target = st.route.target if st is not None and st.route is not None and st.route.target else (nan, nan)
        remaining = s.route_remaining
        self.mav.send(mav.MAVLink_lease_status_message(
            self.boot_ms(t), b.epoch or 0, b.owner or 0, b.owner_compid if b.owner else 0,
            wire_index(cur.index if cur else None), cur.newest_sub[0] if cur and cur.newest_sub else NO_INDEX,
            int(cur.holder) if cur else int(Holder.NONE), int(cur.claimed) if cur else 0, len(b.scheduled),
            s.state, int(b.last_reason),
            0xFFFFFFFF if age is None else int(min(age, 4e6) * 1000), start[0], start[1], target[0], target[1],
            s.displacement, st.max_displacement if st is not None and math.isfinite(st.max_displacement) else nan,
            remaining, min(65535, s.trail_points)))


BUILDERS: dict[int, Callable[[Telemetry, float], None]] = {
    mav.MAVLINK_MSG_ID_SYS_STATUS: Telemetry._sys_status,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: Telemetry._extended_sys_state,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: Telemetry._gps_raw,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: Telemetry._position,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: Telemetry._local_position,
    mav.MAVLINK_MSG_ID_ATTITUDE: Telemetry._attitude,
    mav.MAVLINK_MSG_ID_HOME_POSITION: Telemetry._home,
    mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION: Telemetry._autopilot_version,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: Telemetry._mission_current,
    mav.MAVLINK_MSG_ID_CONTROL_STATUS: Telemetry._control_status,
    mav.MAVLINK_MSG_ID_LEASE_STATUS: Telemetry._lease_status,
    mav.MAVLINK_MSG_ID_HEARTBEAT: Telemetry._heartbeat,
    MSG_ID_CURRENT_MODE: Telemetry._current_mode,
}

