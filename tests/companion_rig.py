"""A companion in-process between a scripted ArduPilot stand-in and ground stations, stepped in simulated time.

``FakeAutopilot`` answers the way the Rover firmware was measured to (docs/architecture.md §11, and the
firmware's README): it switches mode on DO_SET_MODE and acknowledges, arms on COMPONENT_ARM_DISARM, drives a unicycle
on GUIDED velocity targets and stops one 3 s after the last, and reports LOCAL_POSITION_NED, ATTITUDE,
EKF_STATUS_REPORT and its heartbeat. It is for the fast tests of routing and engagement; the behaviour against the real
firmware is tested in ``test_companion_firmware.py``.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from gcs.station import GroundStation
from vehicle.app import DT
from vehicle.companion.app import Companion
from vehicle.params import Params

GUIDED, HOLD, MANUAL = 15, 4, 0


class FakeAutopilot:
    def __init__(self, sysid: int = 1, autopilot: int = apm.MAV_AUTOPILOT_ARDUPILOTMEGA,
                 mav_type: int = apm.MAV_TYPE_GROUND_ROVER) -> None:
        self.enc = apm.MAVLink(None, sysid, 1)
        self.parser = apm.MAVLink(None, 0, 0)
        self.parser.robust_parsing = True
        self.autopilot, self.mav_type = autopilot, mav_type
        self.mode, self.armed = MANUAL, False
        self.x = self.y = self.yaw = 0.0
        self.speed = self.yaw_rate = 0.0
        self.target_speed = 0.0
        self.target_at = -math.inf
        # how the speed follows (m/s^2; None: at once): toward a GUIDED target (``brake``), and with none, in HOLD
        # or any mode that does not drive (``roll``): ArduPilot Rover's HOLD sets the throttle to zero and the rover
        # rolls on, so a roll far below the brake is a rover that coasts
        self.brake: float | None = None
        self.roll: float | None = None
        self.ekf_ok = True
        self.silent = False  # stops answering and reporting (a cut cable)
        self.received: list = []  # every message the companion sent, in order
        self.params = {"MAV_GCS_SYSID": 255.0}
        self.out: list[bytes] = []
        self.next_report = 0.0
        self.next_heartbeat = 0.0

    def _send(self, msg) -> None:
        self.out.append(bytes(msg.pack(self.enc)))
        self.enc.seq = (self.enc.seq + 1) % 256

    def receive(self, data: bytes, t: float) -> None:
        for m in self.parser.parse_buffer(data) or []:
            if m.get_type() == "BAD_DATA":
                continue
            self.received.append(m)
            if self.silent:
                continue
            kind = m.get_type()
            if kind == "COMMAND_LONG" and m.command == apm.MAV_CMD_DO_SET_MODE:
                self.mode = int(m.param2)
                self._ack(m, apm.MAV_RESULT_ACCEPTED)
            elif kind == "COMMAND_LONG" and m.command == apm.MAV_CMD_COMPONENT_ARM_DISARM:
                self.armed = m.param1 >= 0.5
                self._ack(m, apm.MAV_RESULT_ACCEPTED)
            elif kind == "COMMAND_LONG":
                self._ack(m, apm.MAV_RESULT_ACCEPTED)
            elif kind == "SET_POSITION_TARGET_LOCAL_NED" and self.mode == GUIDED:
                self.target_speed, self.yaw_rate, self.target_at = m.vx, m.yaw_rate, t
                if self.brake is None:
                    self.speed = m.vx
            elif kind in ("PARAM_REQUEST_READ", "PARAM_SET"):
                name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode()
                if kind == "PARAM_SET" and name in self.params:
                    self.params[name] = float(m.param_value)
                if name in self.params:
                    self._send(apm.MAVLink_param_value_message(name.encode(), self.params[name],
                                                               apm.MAV_PARAM_TYPE_INT16, len(self.params), 0))

    def _ack(self, m, result: int) -> None:
        self._send(apm.MAVLink_command_ack_message(m.command, result, 0, 0, m.get_srcSystem(),
                                                   m.get_srcComponent()))

    def _drives(self, t: float) -> bool:
        """Whether it follows its last target now: GUIDED, armed, a target within 3 s."""
        return self.mode == GUIDED and t - self.target_at <= 3.0 and self.armed

    def _estimator_report(self, ms: int):
        return apm.MAVLink_ekf_status_report_message(0x1F if self.ekf_ok else 0x03, 0, 0, 0, 0, 0, 0)

    def step(self, t: float, dt: float) -> list[bytes]:
        """Physics and reports for ``dt``; the frames it sends now."""
        if self._drives(t):
            if self.brake is not None:
                step = self.brake * dt
                self.speed += max(-step, min(step, self.target_speed - self.speed))
        elif self.roll is not None:
            self.speed = math.copysign(max(0.0, abs(self.speed) - self.roll * dt), self.speed)
            self.yaw_rate = 0.0
        else:
            self.speed = self.yaw_rate = 0.0
        self.yaw += self.yaw_rate * dt
        self.x += self.speed * math.cos(self.yaw) * dt
        self.y += self.speed * math.sin(self.yaw) * dt
        if self.silent:
            self.out.clear()
            return []
        if t >= self.next_heartbeat:
            self.next_heartbeat = t + 1.0
            base = apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (apm.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
            self._send(apm.MAVLink_heartbeat_message(self.mav_type, self.autopilot, base, self.mode, 4, 3))
        if t >= self.next_report:
            self.next_report = t + 0.1
            ms = int(t * 1000)
            vx, vy = self.speed * math.cos(self.yaw), self.speed * math.sin(self.yaw)
            self._send(apm.MAVLink_local_position_ned_message(ms, self.x, self.y, 0.0, vx, vy, 0.0))
            self._send(apm.MAVLink_attitude_message(ms, 0.0, 0.0, self.yaw, 0.0, 0.0, self.yaw_rate))
            self._send(self._estimator_report(ms))
        out, self.out = self.out, []
        return out

    def sent(self, kind: str, since: int = 0) -> list:
        return [m for m in self.received[since:] if m.get_type() == kind]


class Rig:
    """The companion, the stand-in autopilot and any number of ground stations, stepped together at 50 Hz.

    ``deliver(station, t) -> bool`` decides, per station and moment, whether its traffic crosses the radio (both
    ways): the loss model of a test."""

    def __init__(self, params: Params | None = None, autopilot: FakeAutopilot | None = None, **options) -> None:
        self.ap = autopilot or FakeAutopilot()
        self.t = 0.0
        self.to_ground: list[bytes] = []
        self.companion = Companion(params or Params(), lambda b: self.ap.receive(b, self.t), self.to_ground.append,
                                   **options)
        self.stations: list[GroundStation] = []
        self.deliver = lambda station, t: True
        self.ground_log: list[bytes] = []  # every frame sent to the ground side

    def station(self, sysid: int = 255, target_comp: int = 191, **kw) -> GroundStation:
        gs = GroundStation(sysid, 190, target=1, target_comp=target_comp, **kw)
        self.stations.append(gs)
        return gs

    def send_as(self, gs: GroundStation, build) -> None:
        """Send one message built by ``build(gs.mav)`` (e.g. a command to the autopilot) from station ``gs``."""
        gs.mav.send(build(gs.mav))

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.t = round(self.t + DT, 9)
            t = self.t
            c = self.companion
            for frame in self.ap.step(t, DT):
                c.from_autopilot(frame, t)
            for gs in self.stations:
                frames = gs.tick(t)
                if self.deliver(gs, t):
                    for f in frames:
                        c.from_ground(f, t, ("127.0.0.1", 10000 + gs.sysid))
            c.tick(t)
            out, self.to_ground[:] = list(self.to_ground), []
            for gs in self.stations:
                if self.deliver(gs, t):
                    for f in out:
                        gs.feed(f, t)
            self.ground_log.extend(out)

    def run(self, seconds: float, until=None) -> bool:
        """Step for ``seconds`` of simulated time, or until ``until()``; whether ``until`` came true."""
        for _ in range(int(round(seconds / DT))):
            if until is not None and until():
                return True
            self.step()
        return until() if until is not None else False

    def ground_messages(self, kind: str | None = None) -> list:
        """Every frame the ground side has been sent, parsed (returnlink's messages included)."""
        from link import dialect

        mav = dialect.load()
        parser = mav.MAVLink(None, 0, 0)
        parser.robust_parsing = True
        out = []
        for f in self.ground_log:
            for m in parser.parse_buffer(f) or []:
                if kind is None or m.get_type() == kind:
                    out.append(m)
        return out
