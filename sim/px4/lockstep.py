"""PX4 and its physics in lockstep: one PX4 SITL process, its HIL bridge and its GCS MAVLink port, for a plant on the
simulator loop (``sim.plants.px4``; docs/architecture.md §10.1).

``PX4Lockstep`` starts PX4 (``process``), answers its simulator link by stepping a pymunk robot (``bridge``: one
HIL_SENSOR per 4 ms physics step, PX4's wheel commands back), reads everything PX4 says on its GCS link (UDP
18570+i) into a ``Tap`` (the truth about it: nav state, arming, estimate, version, its clock), lets a caller send
it MAVLink on that link, and stops it. The radio, the operator and the record around it are the caller's.

PX4's GCS link answers whoever spoke to it last, and until someone has it speaks to the port its start-up script
names (PX4's own script: UDP 14550, every ground station's). The run's PX4 is started speaking to the lockstep's own
socket (``PX4Process(gcs_port=...)``), so nothing of it reaches another program; and the lockstep still speaks
first, as soon as PX4 is up: a REQUEST_MESSAGE for AUTOPILOT_VERSION (its version for
metrics.json) from a system id that is no ground station and in a message that is no HEARTBEAT, so PX4 learns where
to send without counting it as its data link (PX4 counts only a GCS-type HEARTBEAT as one: Commander's
``heartbeat_type_gcs``). From then on the only GCS PX4 hears is what the loop's radio delivers.

The same socket is the bridge's second clock (``HilBridge(clock=...)``): every physics step drains what PX4 sent
into ``pending`` (held for the loop's next tick, stamped with the time it arrived) and reads PX4's ``time_boot_ms``
from it, so the bridge paces itself on how far PX4 has got also while disarmed (PX4 sends no wheel commands then).
"""

from __future__ import annotations

import math
import socket
from collections.abc import Callable
from pathlib import Path

from pymavlink.dialects.v20 import common as mav

from link.mission import Origin
from sim.firmware.rangefinders import Rangefinders, distance_sensors
from sim.px4.bridge import BridgeError, HilBridge
from sim.px4.hil import RoverState, rover_command, to_local
from sim.px4.process import GCS_UDP_PORT, PX4Error, PX4Process, claim_instance
from sim.robots import Robot
from sim.world import World

DT = 0.02  # the loop's tick: what moves around PX4 moves at this pace
PHYS_DT = 0.004  # 250 Hz physics: the IMU rate PX4's SITL expects (IMU_INTEG_RATE); five steps a tick
BOOT_LIMIT_S = 90.0  # simulated seconds PX4 gets, once connected, to an EKF2 position, a home and its pre-arm pass
ACCEPT_TIMEOUT_S = 60.0  # wall seconds PX4 gets from its start to connect to the simulator link (its boot budget)
TRACK_M = 0.58  # airframe 1069's RD_WHEEL_TRACK: the wheel commands are mixed for this track
WHEEL_MAX = 2.2  # airframe 1069's RO_MAX_THR_SPEED: the wheel speed at command 1
TAP_SYSID, TAP_COMPID = 254, 240  # the lockstep's own voice on the GCS link: no GCS, sends no HEARTBEAT
ASK_EVERY_S = 1.0  # how often the boot repeats its version request until PX4 answers

# PX4's HEARTBEAT.custom_mode: main mode in bits 16-23, sub mode in 24-31 (src/modules/commander/px4_custom_mode.h);
# named here as PX4 names the nav states they stand for (vehicle_status.nav_state)
MAIN_MANUAL, MAIN_POSCTL, MAIN_AUTO, MAIN_OFFBOARD = 1, 3, 4, 6
AUTO_LOITER, AUTO_MISSION, AUTO_RTL, AUTO_LAND = 3, 4, 5, 6


class PX4Unusable(PX4Error):
    """The PX4 given cannot run here: it would not start, or it exited before it ever connected to the simulator
    link (a broken build, another platform's binary, a tree missing what its start-up script needs)."""


def custom_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT.custom_mode of PX4 main mode ``main``, sub mode ``sub``."""
    return (main << 16) | (sub << 24)


OFFBOARD = custom_mode(MAIN_OFFBOARD)
HOLD = custom_mode(MAIN_AUTO, AUTO_LOITER)  # PX4's Hold: nav state AUTO_LOITER
RETURN = custom_mode(MAIN_AUTO, AUTO_RTL)
NAV_STATES: dict[int, str] = {
    custom_mode(MAIN_MANUAL): "MANUAL", custom_mode(2): "ALTCTL", custom_mode(MAIN_POSCTL): "POSCTL",
    custom_mode(MAIN_POSCTL, 1): "ORBIT", custom_mode(MAIN_POSCTL, 2): "POSITION_SLOW",
    custom_mode(MAIN_AUTO, 1): "AUTO_READY", custom_mode(MAIN_AUTO, 2): "AUTO_TAKEOFF", HOLD: "AUTO_LOITER",
    custom_mode(MAIN_AUTO, AUTO_MISSION): "AUTO_MISSION", RETURN: "AUTO_RTL",
    custom_mode(MAIN_AUTO, AUTO_LAND): "AUTO_LAND", custom_mode(MAIN_AUTO, 8): "AUTO_FOLLOW_TARGET",
    custom_mode(MAIN_AUTO, 9): "AUTO_PRECLAND", custom_mode(MAIN_AUTO, 10): "AUTO_VTOL_TAKEOFF",
    custom_mode(5): "ACRO", OFFBOARD: "OFFBOARD", custom_mode(7): "STAB", custom_mode(10): "TERMINATION",
}


def nav_state_name(mode: int) -> str:
    """PX4's name of the nav state a HEARTBEAT.custom_mode stands for (main/sub numbers when unknown)."""
    return NAV_STATES.get(mode, f"PX4_{(mode >> 16) & 0xFF}_{(mode >> 24) & 0xFF}")


class Tap:
    """The truth about PX4, read from everything it sends on its GCS link before any radio: nav state, arming, its
    estimate in the true frame, its clock, version, texts and answers. Nothing here reaches the operator except
    through the radio."""

    def __init__(self, origin: Origin) -> None:
        self.origin = origin
        self.mav = mav.MAVLink(None)
        self.mav.robust_parsing = True
        self.sysid: int | None = None  # PX4's system id (instance + 1), from its first HEARTBEAT
        self.mode: int | None = None
        self.armed = False
        self.modes: list[tuple[float, int]] = []  # (t, custom_mode) at every change
        self.version: str | None = None
        self.home = False
        self.ekf_ok = False  # ESTIMATOR_STATUS: a horizontal position, absolute and relative
        self.ekf_origin: tuple[float, float] | None = None  # where PX4's local (0, 0) lies in the true frame
        self.local: tuple[float, float] | None = None  # LOCAL_POSITION_NED (north, east)
        self.time_usec: int | None = None  # PX4's clock: the newest time_boot_ms it reported
        self.texts: list[tuple[float, str]] = []
        self.rejected = 0  # COMMAND_ACKs with a result other than ACCEPTED / IN_PROGRESS

    @property
    def estimate(self) -> tuple[float, float] | None:
        """PX4's estimate in the true frame (None until it has one and a home to place its frame by)."""
        if self.local is None or self.ekf_origin is None:
            return None
        return self.ekf_origin[0] + self.local[0], self.ekf_origin[1] + self.local[1]

    def frames(self, data: bytes, t: float) -> list[bytes]:
        """The MAVLink frames in one datagram, each noted; unparseable bytes are dropped."""
        out = []
        for msg in self.mav.parse_buffer(data) or ():
            if msg.get_type() == "BAD_DATA":
                continue
            out.append(msg.get_msgbuf())
            self._note(msg, t)
        return out

    def _note(self, msg, t: float) -> None:
        kind = msg.get_type()
        boot_ms = getattr(msg, "time_boot_ms", None)
        if boot_ms is not None and (self.time_usec is None or boot_ms * 1000 > self.time_usec):
            self.time_usec = boot_ms * 1000
        if kind == "HEARTBEAT":
            if msg.get_srcComponent() != 1 or msg.autopilot != mav.MAV_AUTOPILOT_PX4:
                return
            self.sysid = msg.get_srcSystem()
            self.armed = bool(msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
            if msg.custom_mode != self.mode:
                self.mode = msg.custom_mode
                self.modes.append((t, msg.custom_mode))
        elif kind == "LOCAL_POSITION_NED":
            self.local = (msg.x, msg.y)
        elif kind == "HOME_POSITION":
            # the home's global position says where PX4's local frame lies: its local (x, y) is that far from it
            hx, hy = to_local(self.origin, msg.latitude / 1e7, msg.longitude / 1e7)
            self.ekf_origin = (hx - msg.x, hy - msg.y)
            self.home = True
        elif kind == "ESTIMATOR_STATUS":
            need = mav.ESTIMATOR_POS_HORIZ_ABS | mav.ESTIMATOR_POS_HORIZ_REL
            self.ekf_ok = msg.flags & need == need
        elif kind == "STATUSTEXT":
            self.texts.append((t, msg.text))
        elif kind == "AUTOPILOT_VERSION" and self.version is None:
            v = msg.flight_sw_version  # major, minor, patch, release type: a byte each
            self.version = f"PX4 v{v >> 24 & 0xFF}.{v >> 16 & 0xFF}.{v >> 8 & 0xFF}"
        elif kind == "COMMAND_ACK" and msg.result not in (mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_IN_PROGRESS):
            self.rejected += 1


class PX4Lockstep:
    """One PX4 in lockstep with ``robot`` in ``world``: ``start``, ``boot``, then ``frames`` to move time on;
    ``drain`` reads what it said, ``send`` talks to it; ``close`` stops it (always, in a ``finally``). ``t_sim`` is
    the physics' own time since PX4 connected; ``boot_s`` where scenario time 0 lies on it."""

    def __init__(self, world: World, robot: Robot, px4_dir: Path, params: dict[str, float],
                 origin: Origin | None = None, seed: int = 0, log_path: Path | None = None,
                 accept_timeout_s: float = ACCEPT_TIMEOUT_S, boot_limit_s: float = BOOT_LIMIT_S,
                 rangefinders: Rangefinders | None = None) -> None:
        """``rangefinders``: the rover's (``sim.firmware.rangefinders``), sent to PX4 as DISTANCE_SENSOR on its
        simulator link at their own pace; None, a rover without."""
        self.world, self.robot = world, robot
        self.rangefinders = rangefinders
        self.px4_dir = Path(px4_dir)
        self.params = dict(params)
        self.origin = origin or Origin()
        self.seed = seed
        self.log_path = log_path
        self.accept_timeout_s, self.boot_limit_s = accept_timeout_s, boot_limit_s
        self.tap = Tap(self.origin)
        self.process: PX4Process | None = None
        self.bridge: HilBridge | None = None
        self.sock: socket.socket | None = None
        self.px4_addr: tuple[str, int] | None = None
        self.pending: list[bytes] = []  # what PX4 said since the last ``drain``
        self.cmd = (0.0, 0.0)  # the rover's (speed, yaw rate) command from PX4's newest wheel outputs
        self.t_sim = 0.0
        self.boot_s = 0.0
        self._now = -1.0  # the scenario time frames read now are stamped with (negative while booting)
        self._next_tick = DT

    def start(self) -> None:
        """Claim an instance, start PX4 and wait (``accept_timeout_s`` wall) for it to connect to the bridge."""
        instance, server = claim_instance()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.px4_addr = ("127.0.0.1", GCS_UDP_PORT + instance)
        self.bridge = HilBridge(server, self.origin, clock=self._clock, watch=[self.sock], seed=self.seed)
        try:
            self.process = PX4Process(self.px4_dir, instance, self.params,
                                      gcs_port=self.sock.getsockname()[1]).start()
        except PX4Error as e:
            raise PX4Unusable(str(e)) from None
        try:
            self.bridge.accept(timeout=self.accept_timeout_s, alive=self.process.alive)
        except BridgeError as e:
            words = f"{e}; its last words:\n{self.process.log_tail()}"
            raise (PX4Error if self.process.alive() else PX4Unusable)(words) from None

    def close(self) -> None:
        """PX4 first (while the bridge still holds the instance's port), then the sockets."""
        if self.process is not None:
            self.process.stop(keep_log=self.log_path)
        if self.bridge is not None:
            self.bridge.close()
        if self.sock is not None:
            self.sock.close()

    def send(self, data: bytes) -> None:
        """A MAVLink frame to PX4's GCS link."""
        if self.sock is not None and self.px4_addr is not None:
            self.sock.sendto(data, self.px4_addr)

    def _clock(self) -> int | None:
        """The bridge's second clock: drain the GCS link, answer PX4's newest time."""
        self._read()
        return self.tap.time_usec

    def _read(self) -> None:
        while True:
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return
            except OSError:  # a refused datagram reported back (PX4 not bound yet): nothing to read
                return
            self.pending += self.tap.frames(data, self._now)

    def drain(self, t: float) -> list[bytes]:
        """Everything PX4 said since the last drain."""
        self._now = t
        self._read()
        out, self.pending = self.pending, []
        return out

    def _state(self) -> RoverState:
        r = self.robot
        x, y, yaw = r.pose
        v = r.body.velocity
        return RoverState(x, y, yaw, v.x, v.y, r.true_speed, r.accel, r.body.angular_velocity)

    def _step(self) -> None:
        """One physics step: the sensors of the state reached go to PX4, its newest wheel commands drive the next."""
        extra = ()
        rf = self.rangefinders
        if rf is not None and rf.due(self.t_sim):
            x, y, yaw = self.robot.pose
            extra = distance_sensors(rf.measure(self.t_sim, x, y, yaw), self.bridge.time_usec // 1000)
        try:
            w = self.bridge.step(self._state(), PHYS_DT, extra)
        except BridgeError as e:
            alive = "running" if self.process.alive() else "exited"
            raise PX4Error(f"{e} (PX4 {alive}); its last words:\n{self.process.log_tail()}") from None
        r = self.robot
        self.cmd = rover_command(w, TRACK_M, WHEEL_MAX)
        r.command(*self.cmd)
        r.before_step(PHYS_DT)
        self.world.step(PHYS_DT)
        r.after_step(PHYS_DT)
        self.t_sim += PHYS_DT

    def frames(self, until: float, at_tick: Callable[[float], None]) -> None:
        """Physics steps until ``until`` (physics time), calling ``at_tick(t_sim)`` whenever it crosses a multiple
        of DT."""
        while self.t_sim < until - 1e-9:
            self._step()
            if self.t_sim >= self._next_tick - 1e-9:
                self._next_tick += DT
                self._now = self.t_sim - self.boot_s
                at_tick(self.t_sim)

    def boot(self) -> None:
        """Physics with the robot still until PX4 has a home and an EKF2 horizontal position (absolute and
        relative) and has said its version: scenario time 0 is a PX4 as ready as the native vehicle at its boot.
        Its one pre-arm failure left then is "No connection to the ground control station" (with NAV_DLL_ACT set,
        PX4 arms only with a GCS heartbeat), which only the operator's first heartbeat can clear, and PX4 does not
        report the pre-arm bit of SYS_STATUS (measured: absent from present, enabled and health), so there is no
        more to wait for. The version is asked for (the first request is what makes PX4 send to us) every second
        until it answers."""
        asked = [-math.inf]
        ask = mav.MAVLink(None, srcSystem=TAP_SYSID, srcComponent=TAP_COMPID)

        def listen(t_sim: float) -> None:
            self.pending.clear()  # nobody hears PX4 before scenario time 0
            if self.tap.version is None and t_sim - asked[0] >= ASK_EVERY_S:
                asked[0] = t_sim
                target = self.tap.sysid or 0  # 0: only so that PX4 learns where to send (it ignores the rest)
                self.send(mav.MAVLink_command_long_message(
                    target, 1 if target else 0, mav.MAV_CMD_REQUEST_MESSAGE, 0,
                    mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0).pack(ask))

        tap = self.tap
        while not (tap.home and tap.ekf_ok and tap.version is not None):
            self.frames(self.t_sim + DT, listen)
            if self.t_sim > self.boot_limit_s:
                missing = [name for name, ok in (("a home", tap.home), ("an EKF2 position", tap.ekf_ok),
                                                  ("its version", tap.version is not None)) if not ok]
                raise PX4Error(f"PX4 had no {', no '.join(missing)} after {self.boot_limit_s:g} simulated s; "
                               f"its last words:\n{self.process.log_tail()}")
        self.pending.clear()
        self.boot_s = self.t_sim
        self._now = 0.0
        tap.modes = [(0.0, tap.mode)] if tap.mode is not None else []
