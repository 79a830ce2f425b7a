"""The firmware and its physics in lockstep: one ArduPilot SITL process, its JSON bridge and its MAVLink port.

``Lockstep`` starts the firmware (``process``), answers its servo packets by stepping a pymunk robot (``bridge``;
with the rover's rangefinders in each answer when it has them, ``rangefinders``),
reads everything it says on SERIAL0 into a ``Tap`` (the truth about it: modes, arming, estimate, version), lets a
caller send it MAVLink, and stops it. What happens around it, a scenario's radio and operator (``run``) or a ground
station of your own (``serve``), is the caller's; this module knows nothing of either.

Before scenario time starts the firmware boots and aligns (its EKF needs a GPS fix and an origin) with the robot
standing still and nobody talking to it; ``boot`` returns once it is as ready as the native vehicle is at its boot.
"""

from __future__ import annotations

import socket
from collections.abc import Callable
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

from sim.firmware.bridge import SKID_FUNCTIONS, FrameRules, FrameVerdict, ServoMap, parse_servo, state_reply
from sim.firmware.process import FirmwareError, FirmwareProcess, claim_instance
from sim.firmware.rangefinders import Rangefinders
from sim.robots import Robot
from sim.world import World

DT = 0.02  # the native vehicle's tick: what moves around the firmware moves at this pace
RATE = 200  # the firmware's physics frame rate (--rate): below about 65 Hz its gyro-rate pre-arm check fails
SPEEDUP = 1000  # far beyond what the lockstep reaches: the bridge, not the firmware's clock, sets the pace
BOOT_LIMIT_S = 120.0  # simulated seconds the firmware gets to boot and find its home
RECV_TIMEOUT_S = 10.0  # wall seconds without a servo packet before the firmware counts as hung
SERVO_CHANNELS = 4  # outputs whose function the bridge reads at boot (a rover's steering and throttle are among them)
TAP_SYSID, TAP_COMPID = 200, 240  # the bridge's own voice at boot: outside [MAV_GCS_SYSID, MAV_GCS_SYSID_HI]
HOME = (-35.3632621, 149.1652374, 584.0)  # ArduPilot's SITL home (CMAC); world (0, 0) lies here
MODE_NAMES = {0: "MANUAL", 1: "ACRO", 2: "LEARNING", 3: "STEERING", 4: "HOLD", 5: "LOITER", 6: "FOLLOW",
              7: "SIMPLE", 8: "DOCK", 9: "CIRCLE", 10: "AUTO", 11: "RTL", 12: "SMART_RTL", 15: "GUIDED",
              16: "INITIALISING"}
SKID_PARAMS = {f"SERVO{ch}_FUNCTION": fn for ch, fn in SKID_FUNCTIONS.items()}


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
        self.servo_functions: dict[int, int] = {}  # output channel -> SERVOn_FUNCTION, as the firmware reports

    def frames(self, data: bytes, t: float) -> list[bytes]:
        """The MAVLink frames in one datagram, each noted; unparseable bytes are dropped (a radio would not carry
        half a frame either)."""
        out = []
        for msg in self.mav.parse_buffer(data) or ():
            kind = msg.get_type()
            if kind == "BAD_DATA":
                continue
            out.append(msg.get_msgbuf())
            if msg.get_srcComponent() == 1:
                note = self._NOTES.get(kind)
                if note is not None:
                    note(self, msg, t)
        return out

    # ----- what each of the autopilot's messages says (one small method a kind, looked up by ``_NOTES``) ------
    def _heartbeat(self, msg, t: float) -> None:
        self.armed = bool(msg.base_mode & apm.MAV_MODE_FLAG_SAFETY_ARMED)
        if msg.custom_mode != self.mode:
            self.mode = msg.custom_mode
            self.modes.append((t, msg.custom_mode))

    def _local_position(self, msg, t: float) -> None:
        self.estimate = (msg.x, msg.y)

    def _home(self, msg, t: float) -> None:
        self.home = True

    def _ekf_status(self, msg, t: float) -> None:
        f = msg.flags
        self.ekf_ok = bool(f & apm.EKF_POS_HORIZ_ABS) and not f & apm.EKF_CONST_POS_MODE

    def _sys_status(self, msg, t: float) -> None:
        self.prearm_ok = bool(msg.onboard_control_sensors_health & apm.MAV_SYS_STATUS_PREARM_CHECK)

    def _statustext(self, msg, t: float) -> None:
        text = msg.text
        self.texts.append((t, text))
        if self.version is None and text.startswith("ArduRover"):
            self.version = text.strip()

    def _param_value(self, msg, t: float) -> None:
        if msg.param_id.startswith("SERVO") and msg.param_id.endswith("_FUNCTION"):
            ch = msg.param_id[5:-9]
            if ch.isdigit():
                self.servo_functions[int(ch)] = int(round(msg.param_value))

    def _command_ack(self, msg, t: float) -> None:
        if msg.result not in (apm.MAV_RESULT_ACCEPTED, apm.MAV_RESULT_IN_PROGRESS):
            self.rejected += 1

    _NOTES = {"HEARTBEAT": _heartbeat, "LOCAL_POSITION_NED": _local_position, "HOME_POSITION": _home,
              "EKF_STATUS_REPORT": _ekf_status, "SYS_STATUS": _sys_status, "STATUSTEXT": _statustext,
              "PARAM_VALUE": _param_value, "COMMAND_ACK": _command_ack}


class Lockstep:
    """One firmware process in lockstep with ``robot`` in ``world``: ``start``, ``boot``, then ``frames`` to move
    time on; ``drain`` reads what it said, ``send`` talks to it; ``close`` stops it (always, in a ``finally``)."""

    def __init__(self, world: World, robot: Robot, firmware: Path, params: dict[str, float],
                 speedup: float = SPEEDUP, log_path: Path | None = None, scripts: tuple[Path, ...] = (),
                 rangefinders: Rangefinders | None = None) -> None:
        """``scripts``: Lua files for the firmware's ``scripts/`` folder (its working directory's, as the SD card's
        ``APM/scripts/`` on a flight controller); they run when the parameters set SCR_ENABLE 1. ``rangefinders``:
        the rover's, measured from the world at their own pace into each answer (``params`` must give the firmware
        them: ``sim.firmware.rangefinders.params``); None, a rover without."""
        self.world, self.robot = world, robot
        self.scripts = tuple(Path(s) for s in scripts)
        self.firmware = Path(firmware)
        self.params = dict(params)
        self.speedup = speedup
        self.log_path = log_path
        self.tap = Tap()
        self.rules = FrameRules()
        self.servo = ServoMap(robot.max_speed)  # until the firmware has said what its outputs are
        self.process: FirmwareProcess | None = None
        self.json_sock: socket.socket | None = None
        self.mav_sock: socket.socket | None = None
        self.fw_addr: tuple[str, int] | None = None
        self.cmd = (0.0, 0.0)  # the rover's (speed, yaw rate) command from the last frame
        self.t_fw = 0.0  # the physics' own time since the firmware started (the JSON timestamps)
        self.boot_s = 0.0  # simulated seconds the firmware took to boot
        self._next_tick = DT
        self._sent: bytes | None = None
        self.rangefinders = rangefinders
        x0, y0, yaw0 = robot.pose
        ranges = rangefinders.measure(0.0, x0, y0, yaw0) if rangefinders is not None else None
        self._next = state_reply(0.0, x0, y0, yaw0, 0.0, 0.0, 0.0, 0.0, 0.0, ranges)

    def start(self) -> None:
        instance, self.json_sock = claim_instance()
        self.json_sock.settimeout(RECV_TIMEOUT_S)
        self.mav_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.mav_sock.bind(("127.0.0.1", 0))
        self.mav_sock.setblocking(False)
        fw_port = self.mav_sock.getsockname()[1]
        proc = FirmwareProcess(self.firmware, instance, [])
        defaults = proc.workdir / "returnlink.parm"
        defaults.write_text("".join(f"{k} {v:g}\n" for k, v in self.params.items()))
        if self.scripts:
            folder = proc.workdir / "scripts"
            folder.mkdir(exist_ok=True)
            for script in self.scripts:
                (folder / script.name).write_bytes(script.read_bytes())
        home = ",".join(f"{v:.7f}" for v in HOME) + ",0"
        # ArduPilot's own SITL rover defaults sit beside a binary built the documented way
        # (Tools/autotest/default_params/rover.parm, copied next to it); ours go on top
        beside = self.firmware.with_name("rover.parm")
        files = f"{beside},{defaults}" if beside.is_file() else str(defaults)
        proc.args = ["--model", "JSON", "--rate", str(RATE), "--speedup", f"{self.speedup:g}", "-w",
                     "--defaults", files, "--serial0", f"udpclient:127.0.0.1:{fw_port}", "--home", home,
                     "--sysid", "1"]
        self.process = proc.start()

    def close(self) -> None:
        if self.process is not None:
            self.process.stop(keep_log=self.log_path)
        for s in ("json_sock", "mav_sock"):
            sock = getattr(self, s, None)
            if sock is not None:
                sock.close()

    def send(self, data: bytes) -> None:
        """A MAVLink frame to the firmware's SERIAL0 (dropped until it has spoken: its address is not known)."""
        if self.fw_addr is not None:
            self.mav_sock.sendto(data, self.fw_addr)

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
        self.cmd = (speed, yaw_rate)
        r.command(speed, yaw_rate)
        r.before_step(dt)
        self.world.step(dt)
        r.after_step(dt)
        self.t_fw += dt
        x, y, yaw = r.pose
        v = r.body.velocity
        ranges = None
        rf = self.rangefinders
        if rf is not None:
            ranges = rf.measure(self.t_fw, x, y, yaw) if rf.due(self.t_fw) else rf.last
        self._next = state_reply(self.t_fw, x, y, yaw, v.x, v.y, r.true_speed, r.accel, r.body.angular_velocity,
                                 ranges)

    def frames(self, until: float, at_tick: Callable[[float], None]) -> None:
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

    def drain(self, t: float) -> list[bytes]:
        frames = []
        while True:
            try:
                data, addr = self.mav_sock.recvfrom(65536)
            except BlockingIOError:
                return frames
            self.fw_addr = addr
            frames += self.tap.frames(data, t)

    def boot(self) -> None:
        """Physics with the robot still until the firmware has a home, its EKF fuses GPS and its pre-arm checks
        pass (both are needed: the pre-arm bit was seen set while arming still failed on the AHRS), so scenario
        time starts with a firmware as ready as the native vehicle is at its boot. Its version is asked for once
        (DO_SEND_BANNER, from a system id outside the GCS range, so it counts as no ground station), and so are the
        functions of its outputs, from which the bridge maps PWM to the rover's speed and turn rate."""
        asked = []

        def listen(_t: float) -> None:
            self.drain(-1.0)
            if not asked and self.fw_addr is not None:
                asked.append(True)
                for request in self._boot_requests():
                    self.send(request)

        while not (self.tap.home and self.tap.prearm_ok and self.tap.ekf_ok
                   and len(self.tap.servo_functions) == SERVO_CHANNELS):
            self.frames(self.t_fw + DT, listen)
            if self.t_fw > BOOT_LIMIT_S:
                raise FirmwareError("the firmware found no home, no EKF position or failed its pre-arm checks for "
                                    f"{BOOT_LIMIT_S:g} simulated s; its last words:\n{self.process.log_tail()}")
        try:
            self.servo = ServoMap(self.robot.max_speed, self.tap.servo_functions)
        except ValueError as e:
            raise FirmwareError(f"the firmware's outputs cannot drive this rover: {e}") from None
        self.boot_s = self.t_fw
        self.tap.modes = [(0.0, self.tap.mode)] if self.tap.mode is not None else []

    @staticmethod
    def _boot_requests() -> list[bytes]:
        """Its version banner, and the functions of its first outputs (the bridge maps PWM by what they are)."""
        mav = apm.MAVLink(None, srcSystem=TAP_SYSID, srcComponent=TAP_COMPID)
        out = [apm.MAVLink_command_long_message(1, 1, apm.MAV_CMD_DO_SEND_BANNER, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)]
        out += [apm.MAVLink_param_request_read_message(1, 1, f"SERVO{ch}_FUNCTION".encode(), -1).pack(mav)
                for ch in range(1, SERVO_CHANNELS + 1)]
        return out

