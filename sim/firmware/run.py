"""``returnlink sim run SCENARIO --vehicle ardurover``: the real ArduPilot Rover firmware in a scenario's world.

The scenario's pymunk rover (walls stay collisions) is driven by the firmware's servo outputs through the JSON
bridge, lockstep: the firmware asks for a physics step per frame (200 Hz), the physics steps and answers, so
simulated time is the physics' own and the run goes as fast as both processes allow. Every 20 ms of it (the native
tick) the rest of the world moves: the firmware's MAVLink traffic (its SERIAL0, sent to a UDP socket of ours) is
read, each frame handed through ``link.radio`` to the ground stations, the scripted operator and the scenario's
timed events act, and what the stations send goes through the radio to the firmware. Its GCS failsafe hears
exactly what the radio delivers. The same seed gives the same radio fates, sensors-free physics and operator as
the native rover flying the scenario, so the firmware's failsafes are compared in the same world.

Before the scenario's clock starts the firmware boots and aligns (its EKF needs a GPS fix and an origin): the
robot stands still at its start, no station talks to it, and the run waits (in simulated time) until the firmware
reports a home position. Scenario time 0 is that moment.

The firmware's own simulated GPS stays on in the scenario's GPS-denied zones: ArduPilot's SITL rover gets no wheel
odometry from this bridge, so without GPS its EKF would have no position source at all, while the native vehicle
dead-reckons on odometry there. Switching it off would compare a blind firmware with a dead-reckoning vehicle,
measuring the sensor suite rather than the link-loss behaviour this comparison is for.
"""

from __future__ import annotations

import gc
import math
import socket
import struct
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

from link.proxy import RadioReport
from link.radio import LinkState, Radio, subsystem_rng
from link.transports import LockstepBus
from sim.firmware.bridge import FrameRules, FrameVerdict, ServoMap, parse_servo, state_reply
from sim.firmware.operator import GCS_COMPID, RETURN_MODES, FirmwareOperator
from sim.firmware.process import FirmwareError, FirmwareProcess, claim_instance
from sim.robots import make_robot
from sim.runner import TLOG_EPOCH_US
from sim.scenario import Scenario
from vehicle.app import DT  # the native vehicle's tick: radio, stations, operator and events move at this pace

RATE = 200  # the firmware's physics frame rate (--rate): below about 65 Hz its gyro-rate pre-arm check fails
SPEEDUP = 1000  # far beyond what the lockstep reaches: the bridge, not the firmware's clock, sets the pace
BOOT_LIMIT_S = 120.0  # simulated seconds the firmware gets to boot and find its home
RECV_TIMEOUT_S = 10.0  # wall seconds without a servo packet before the firmware counts as hung
TAP_SYSID, TAP_COMPID = 200, 240  # the runner's own voice at boot: outside [MAV_GCS_SYSID, MAV_GCS_SYSID_HI]
HOME = (-35.3632621, 149.1652374, 584.0)  # ArduPilot's SITL home (CMAC); world (0, 0) lies here

_TLOG_STAMP = struct.Struct(">Q").pack

FS_ACTION: dict[str, int] = {"ardupilot-hold": 2, "ardupilot-rtl": 1, "ardupilot-smartrtl": 4}  # per policy
MODE_NAMES = {0: "MANUAL", 1: "ACRO", 2: "LEARNING", 3: "STEERING", 4: "HOLD", 5: "LOITER", 6: "FOLLOW",
              7: "SIMPLE", 8: "DOCK", 9: "CIRCLE", 10: "AUTO", 11: "RTL", 12: "SMART_RTL", 15: "GUIDED",
              16: "INITIALISING"}


def firmware_params(policy: str, lnk_timeout: float, max_speed: float) -> dict[str, float]:
    """What a firmware run sets on top of ArduPilot's own SITL rover defaults, and why:
    - the policy's failsafe: FS_GCS_ENABLE 1, FS_ACTION per policy, FS_GCS_TIMEOUT = the scenario's LNK_TIMEOUT
      (at least 2 s, the firmware's range), so it reacts to the same silence the native vehicle does;
    - FS_THR_ENABLE 0: nobody holds an RC transmitter here, and its radio failsafe would fire at once;
    - CRUISE_SPEED/CRUISE_THROTTLE matching the bridge's throttle scale (full throttle = the rover's top speed), so
      the speed controller's feed-forward is right from the start;
    - WP_RADIUS 1 m: a GUIDED position target counts as reached where the scripted operator moves on."""
    return {"FS_GCS_ENABLE": 1, "FS_ACTION": FS_ACTION[policy], "FS_GCS_TIMEOUT": max(2.0, lnk_timeout),
            "FS_THR_ENABLE": 0, "CRUISE_SPEED": round(max_speed / 2, 3), "CRUISE_THROTTLE": 50, "WP_RADIUS": 1.0}


@dataclass
class Station:
    name: str
    antenna: tuple[float, float]
    power_dbm: float
    alive: bool
    operator: FirmwareOperator | None = None
    state: LinkState | None = None
    down: tuple = field(init=False)
    up: tuple = field(init=False)

    def __post_init__(self) -> None:
        self.down = (("vehicle", self.name), f"downlink.{self.name}")
        self.up = ((self.name, "vehicle"), f"uplink.{self.name}")


class Tap:
    """The truth about the firmware, read from everything it sends before any radio: modes, arming, its estimate,
    its text messages, its answers. Nothing here reaches the operator except through the radio."""

    def __init__(self) -> None:
        self.mav = apm.MAVLink(None)
        self.mav.robust_parsing = True
        self.mode: int | None = None
        self.armed = False
        self.modes: list[tuple[float, int]] = []  # (t, custom_mode) at every change
        self.version: str | None = None
        self.home = False
        self.prearm_ok = False  # SYS_STATUS says its pre-arm checks pass
        self.ekf_ok = False  # EKF_STATUS_REPORT: an absolute horizontal position, out of constant-position mode
        self.estimate: tuple[float, float] | None = None  # LOCAL_POSITION_NED (north, east) from the EKF origin
        self.texts: list[tuple[float, str]] = []
        self.rejected = 0  # COMMAND_ACKs with a result other than ACCEPTED / IN_PROGRESS

    def frames(self, data: bytes, t: float) -> list[bytes]:
        """The MAVLink frames in one datagram, each noted; unparseable bytes are dropped (a radio would not carry
        half a frame either)."""
        out = []
        for msg in self.mav.parse_buffer(data) or ():
            kind = msg.get_type()
            if kind == "BAD_DATA":
                continue
            out.append(msg.get_msgbuf())
            if msg.get_srcComponent() != 1:
                continue
            if kind == "HEARTBEAT":
                self.armed = bool(msg.base_mode & apm.MAV_MODE_FLAG_SAFETY_ARMED)
                if msg.custom_mode != self.mode:
                    self.mode = msg.custom_mode
                    self.modes.append((t, msg.custom_mode))
            elif kind == "LOCAL_POSITION_NED":
                self.estimate = (msg.x, msg.y)
            elif kind == "HOME_POSITION":
                self.home = True
            elif kind == "EKF_STATUS_REPORT":
                f = msg.flags
                self.ekf_ok = bool(f & apm.EKF_POS_HORIZ_ABS) and not f & apm.EKF_CONST_POS_MODE
            elif kind == "SYS_STATUS":
                self.prearm_ok = bool(msg.onboard_control_sensors_health & apm.MAV_SYS_STATUS_PREARM_CHECK)
            elif kind == "STATUSTEXT":
                text = msg.text
                self.texts.append((t, text))
                if self.version is None and text.startswith("ArduRover"):
                    self.version = text.strip()
            elif kind == "COMMAND_ACK" and msg.result not in (apm.MAV_RESULT_ACCEPTED, apm.MAV_RESULT_IN_PROGRESS):
                self.rejected += 1
        return out


class FirmwareRun:
    """One scenario flown by the firmware. ``run()`` returns self with ``trace`` and the firmware's record; the
    process is stopped when it ends, raises, or is interrupted."""

    kind = "ardurover"

    def __init__(self, scenario: Scenario, seed: int | None = None, policy: str = "ardupilot-smartrtl",
                 firmware: Path | None = None, progress: bool = False, duration: float | None = None,
                 log_path: Path | None = None) -> None:
        if policy not in FS_ACTION:
            raise ValueError(f"policy {policy!r} is not one of the firmware's failsafes ({', '.join(FS_ACTION)})")
        if firmware is None:
            raise ValueError("no firmware binary given")
        self.scenario = sc = scenario
        self.policy = policy
        self.firmware = Path(firmware)
        self.seed = sc.seed if seed is None else seed
        self.duration = sc.duration if duration is None else duration
        self.progress = progress
        self.log_path = log_path
        self.world = sc.world()
        x, y, yaw = sc.start
        self.robot = make_robot("rover", self.world, x, y, yaw, subsystem_rng(self.seed, "robot"))
        self.origin = (x, y)
        self.servo = ServoMap(self.robot.max_speed)
        self.radio = Radio(sc.radio, self.world.attenuation_db, self.seed)
        self.radio_report = RadioReport()
        self.bus = LockstepBus()
        self.stations = {s.name: Station(s.name, (s.x, s.y), s.power_dbm, s.name == sc.operator_station)
                         for s in sc.stations}
        self.op_station = self.stations[sc.operator_station]
        self.operator = FirmwareOperator(sc.route, sc.resume_route, self.origin, sc.attempts,
                                         sysid=next(s.sysid for s in sc.stations if s.name == sc.operator_station))
        self.op_station.operator = self.operator
        self.owner_sysid = self.operator.mav.srcSystem
        self.events = sorted(sc.events, key=lambda e: e.t)
        self.jams: list[tuple[float, float, str]] = []
        self.params = {**firmware_params(policy, float(sc.params.get("LNK_TIMEOUT", 3.0)), self.robot.max_speed)}
        self.lnk_timeout = float(sc.params.get("LNK_TIMEOUT", 3.0))
        self.tap = Tap()
        self.rules = FrameRules()
        self.t = 0.0
        self.boot_s = 0.0  # simulated seconds the firmware took to boot, before scenario time 0
        self.heard: list[float] = []  # scenario times at which the firmware received a frame from the owner
        self.rmse_pairs: list[tuple[float, float, float, float]] = []
        # per tick: (t, true x, true y, est x, est y, mode, link delivery, rssi, speed cmd, yaw rate cmd, armed,
        # collisions so far)
        self.rows: list[tuple] = []
        self.notes: list[str] = []
        self.tlog: list[bytes] = []  # the operator station's traffic, as ``sim.runner.Run`` keeps it
        self.wall = 0.0
        self.stopped = False
        self.process: FirmwareProcess | None = None
        self._fw_addr: tuple[str, int] | None = None
        self._cmd = (0.0, 0.0)
        self.t_fw = 0.0  # the physics' own time since the firmware started (the JSON timestamps)
        self._next_tick = DT
        self._sent: bytes | None = None
        x0, y0, yaw0 = self.robot.pose
        self._next = state_reply(0.0, x0, y0, yaw0, 0.0, 0.0, 0.0, 0.0, 0.0)
        self.next_radio_status = 0.0
        self.metrics: dict | None = None

    # ----- the process and the sockets -----------------------------------------------------------------------
    def _start(self) -> None:
        instance, self.json_sock = claim_instance()
        self.json_sock.settimeout(RECV_TIMEOUT_S)
        self.mav_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.mav_sock.bind(("127.0.0.1", 0))
        self.mav_sock.setblocking(False)
        fw_port = self.mav_sock.getsockname()[1]
        proc = FirmwareProcess(self.firmware, instance, [])
        defaults = proc.workdir / "returnlink.parm"
        defaults.write_text("".join(f"{k} {v:g}\n" for k, v in self.params.items()))
        home = ",".join(f"{v:.7f}" for v in HOME) + ",0"
        # ArduPilot's own SITL rover defaults sit beside a binary built the documented way
        # (Tools/autotest/default_params/rover.parm, copied next to it); ours go on top
        beside = self.firmware.with_name("rover.parm")
        files = f"{beside},{defaults}" if beside.is_file() else str(defaults)
        proc.args = ["--model", "JSON", "--rate", str(RATE), "--speedup", str(SPEEDUP), "-w", "--defaults", files,
                     "--serial0", f"udpclient:127.0.0.1:{fw_port}",
                     "--home", home, "--sysid", "1"]
        self.process = proc.start()

    def _close(self) -> None:
        if self.process is not None:
            self.process.stop(keep_log=self.log_path)
        for s in ("json_sock", "mav_sock"):
            sock = getattr(self, s, None)
            if sock is not None:
                sock.close()

    def _frame(self) -> tuple:
        """The next servo packet that asks for a step (answering repeats on the way), and its source address."""
        while True:
            try:
                data, addr = self.json_sock.recvfrom(512)
            except TimeoutError:
                tail = self.process.log_tail() if self.process else ""
                state = "exited" if self.process and not self.process.alive() else "running but silent"
                raise FirmwareError(f"no servo packet from the firmware for {RECV_TIMEOUT_S:g} s ({state}); "
                                    f"its last words:\n{tail}") from None
            frame = parse_servo(data)
            verdict = self.rules.judge(frame)
            if verdict is FrameVerdict.STEP:
                return frame, addr
            if verdict is FrameVerdict.REPEAT and self._sent is not None:
                self.json_sock.sendto(self._sent, addr)
            elif verdict is FrameVerdict.RESTART:
                raise FirmwareError(f"the firmware restarted (frame counter went back to {frame.frame_count})")

    def _step(self, pwm: tuple[int, ...], dt: float) -> None:
        """One physics step of ``dt`` under ``pwm``; the answer for the firmware's next frame is made now."""
        r = self.robot
        speed, yaw_rate = self.servo.command(pwm, r.true_speed)
        self._cmd = (speed, yaw_rate)
        r.command(speed, yaw_rate)
        r.before_step(dt)
        self.world.step(dt)
        r.after_step(dt)
        self.t_fw += dt
        x, y, yaw = r.pose
        v = r.body.velocity
        self._next = state_reply(self.t_fw, x, y, yaw, v.x, v.y, r.true_speed, r.accel, r.body.angular_velocity)

    def _frames(self, until: float, at_tick) -> None:
        """Answer frames until the physics reaches ``until`` (firmware time), calling ``at_tick(t_fw)`` whenever
        it crosses a multiple of DT.

        Pipelined: a frame is answered at once with the state the physics already reached (stepped under the
        frame before), then the physics steps under the new frame while the firmware computes its next one; the
        two processes work at the same time instead of in turn, for one frame (5 ms) of actuator latency, which
        a real servo chain has too. Everything that talks to the firmware's MAVLink port happens while it waits
        for that answer, so which of its loops sees a message never depends on timing."""
        while self.t_fw < until - 1e-9:
            frame, addr = self._frame()
            if self.t_fw >= self._next_tick - 1e-9:
                self._next_tick += DT
                at_tick(self.t_fw)
            self._sent = self._next
            self.json_sock.sendto(self._next, addr)
            self._step(frame.pwm, 1.0 / frame.frame_rate)

    def _drain(self, t: float) -> list[bytes]:
        frames = []
        while True:
            try:
                data, addr = self.mav_sock.recvfrom(65536)
            except BlockingIOError:
                return frames
            self._fw_addr = addr
            frames += self.tap.frames(data, t)

    # ----- the loop ------------------------------------------------------------------------------------------
    def run(self) -> FirmwareRun:
        w0 = time.perf_counter()
        freeze = gc.get_freeze_count() == 0
        if freeze:
            gc.freeze()
        try:
            self._start()
            self._boot()
            self._loop()
        finally:
            if freeze:
                gc.unfreeze()
            self._close()
        self.wall = time.perf_counter() - w0
        if self.tap.version is None:
            self.tap.version = "ArduRover (version not reported)"
        return self

    def _boot(self) -> None:
        """Physics with the robot still until the firmware has a home, its EKF fuses GPS and its pre-arm checks
        pass (both are needed: the pre-arm bit was seen set while arming still failed on the AHRS), so scenario
        time starts with a firmware as ready as the native vehicle is at its boot. Its version is asked for once
        (DO_SEND_BANNER, from a system id outside the GCS range, so it counts as no ground station)."""
        asked = []

        def listen(_t: float) -> None:
            self._drain(-1.0)
            if not asked and self._fw_addr is not None:
                asked.append(True)
                self.mav_sock.sendto(self._banner_request(), self._fw_addr)

        while not (self.tap.home and self.tap.prearm_ok and self.tap.ekf_ok):
            self._frames(self.t_fw + DT, listen)
            if self.t_fw > BOOT_LIMIT_S:
                raise FirmwareError("the firmware found no home, no EKF position or failed its pre-arm checks for "
                                    f"{BOOT_LIMIT_S:g} simulated s; its last words:\n{self.process.log_tail()}")
        self.boot_s = self.t_fw
        self.tap.modes = [(0.0, self.tap.mode)] if self.tap.mode is not None else []

    @staticmethod
    def _banner_request() -> bytes:
        mav = apm.MAVLink(None, srcSystem=TAP_SYSID, srcComponent=TAP_COMPID)
        return apm.MAVLink_command_long_message(1, 1, apm.MAV_CMD_DO_SEND_BANNER, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)

    def _loop(self) -> None:
        n = int(round(self.duration / DT))
        tty = sys.stderr.isatty()
        shown = [-1]
        boot = self.boot_s

        def tick(t_fw: float) -> None:
            if self.stopped:
                return
            t = self.t = round(t_fw - boot, 9)
            if t <= 0:
                return
            self._tick(t)
            if self.progress and (pct := int(100 * t / self.duration)) != shown[0] and pct % (2 if tty else 25) == 0:
                shown[0] = pct
                bar = "#" * (pct // 4) + "." * (25 - pct // 4)
                print(f"\r  [{bar}] {pct:3d}%  t={t:6.1f} s  {MODE_NAMES.get(self.tap.mode, '?'):<10}",
                      end="" if tty else "\n", file=sys.stderr, flush=True)

        while not self.stopped and self.t < n * DT - 1e-9:
            self._frames(self.t_fw + DT, tick)
        if self.progress and tty:
            print(file=sys.stderr)

    def _tick(self, t: float) -> None:
        bus, radio = self.bus, self.radio
        stations = list(self.stations.values())
        # what the stations receive
        for st in stations:
            for data, _src in bus.receive(st.name, t):
                if st.alive and st.operator is not None:
                    st.operator.feed(data, t)
                    self._log_frame(data, t)
        if self.events and self.events[0].t <= t + 1e-9:
            self._events(t)
        pos = self.robot.pose[:2]
        for st in stations:
            st.state = radio.link(st.antenna, st.power_dbm, pos) if st.alive else None
        # the firmware's frames out through the radio
        frames = self._drain(t)
        if frames:
            live = [st for st in stations if st.state is not None and not self._jammed(st.name, t)]
            for data in frames:
                for st in live:
                    lane, stream = st.down
                    at = radio.arrival(st.state, t, lane, stream)
                    if at is not None:
                        bus.send("vehicle", st.name, data, at)
        # the stations' frames in through the radio
        for st in stations:
            if not st.alive or st.operator is None:
                continue
            sent = st.operator.tick(t)
            for data in sent:
                self._log_frame(data, t)
            if not sent or st.state is None or self._jammed(st.name, t):
                continue
            lane, stream = st.up
            for data in sent:
                at = radio.arrival(st.state, t, lane, stream)
                if at is not None:
                    bus.send(st.name, "vehicle", data, at)
        for data, src in bus.receive("vehicle", t):
            if self._fw_addr is not None:
                self.mav_sock.sendto(data, self._fw_addr)
                if src == self.op_station.name:
                    self.heard.append(t)
        if t >= self.next_radio_status:
            self.next_radio_status = t + 1.0
            op = self.op_station
            if op.alive and op.state is not None and op.operator is not None:
                data = self.radio_report.frame(op.state, jammed=self._jammed(op.name, t))
                op.operator.feed(data, t)
                self._log_frame(data, t)
        self._record(t, pos)

    def _log_frame(self, data: bytes, t: float) -> None:
        self.tlog.append(_TLOG_STAMP(TLOG_EPOCH_US + int(t * 1e6)) + data)

    def _jammed(self, station: str, t: float) -> bool:
        return bool(self.jams) and any(a <= t < b and (not s or s == station) for a, b, s in self.jams)

    def _events(self, t: float) -> None:
        while self.events and self.events[0].t <= t + 1e-9:
            ev = self.events.pop(0)
            st = self.stations.get(ev.station or self.scenario.operator_station)
            if ev.action == "jam":
                self.jams.append((ev.t, ev.t + (ev.duration or math.inf), ev.station))
            elif ev.action == "unjam":
                self.jams = [(a, min(b, t), s) for a, b, s in self.jams]
            elif ev.action == "kill_gcs" and st is not None:
                st.alive = False
            elif ev.action == "revive_gcs" and st is not None:
                st.alive = True
            elif ev.action == "rtl" and st is not None and st.operator is not None:
                st.operator.request_rtl(t)
            elif ev.action == "stop":
                self.stopped = True
            else:
                # leases, claims and returnlink parameters mean nothing to the firmware: said, not faked
                self.notes.append(f"t={ev.t:g} s: event {ev.action!r} does not apply to the ArduPilot firmware")

    def _record(self, t: float, pos: tuple[float, float]) -> None:
        est = self.tap.estimate
        ex, ey = (self.origin[0] + est[0], self.origin[1] + est[1]) if est is not None else (math.nan, math.nan)
        op = self.op_station
        if op.state is None:
            link, rssi = 0.0, math.nan
        else:
            link = 0.0 if self._jammed(op.name, t) else op.state.delivery
            rssi = op.state.rssi_dbm
        mode = -1 if self.tap.mode is None else self.tap.mode
        self.rows.append((t, pos[0], pos[1], ex, ey, mode, link, rssi, self._cmd[0], self._cmd[1], self.tap.armed,
                          self.world.collisions))

    # ----- reading the record --------------------------------------------------------------------------------
    @property
    def firmware_modes(self) -> list[dict]:
        return [{"t": round(t, 3), "mode": MODE_NAMES.get(m, str(m))} for t, m in self.tap.modes]

    def true_at(self, t: float) -> tuple[float, float]:
        k = min(len(self.rows) - 1, max(0, int(round(t / DT)) - 1))
        row = self.rows[k]
        return row[1], row[2]


def in_return_mode(mode: int) -> bool:
    return mode in RETURN_MODES


__all__ = ["FS_ACTION", "FirmwareRun", "FirmwareError", "GCS_COMPID", "MODE_NAMES", "firmware_params"]
