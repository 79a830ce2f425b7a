"""``returnlink sim run SCENARIO --vehicle ardurover``: the real ArduPilot Rover firmware in a scenario's world.

The scenario's pymunk rover (walls stay collisions) is driven by the firmware's servo outputs through the JSON
bridge, lockstep: the firmware asks for a physics step per frame (200 Hz), the physics steps and answers, so
simulated time is the physics' own and the run goes as fast as both processes allow. Every 20 ms of it (the native
tick) the rest of the world moves: the firmware's MAVLink traffic (its SERIAL0, sent to a UDP socket of ours) is
read, each frame handed through ``link.radio`` to the ground stations, the scripted operator and the scenario's
timed events act, and what the stations send goes through the radio to the firmware. Its GCS failsafe hears
exactly what the radio delivers. The same seed gives the same radio fates, sensors-free physics and operator as
the native rover flying the scenario, so the firmware's failsafes are compared in the same world.

Scenario time 0 is the moment the firmware is ready (``Lockstep.boot``: home, EKF on GPS, pre-arm checks passed).

The firmware's own simulated GPS stays on in the scenario's GPS-denied zones: ArduPilot's SITL rover gets no wheel
odometry from this bridge, so without GPS its EKF would have no position source at all, while the native vehicle
dead-reckons on odometry there. Switching it off would compare a blind firmware with a dead-reckoning vehicle,
measuring the sensor suite rather than the link-loss behaviour this comparison is for.
"""

from __future__ import annotations

import gc
import math
import struct
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from link.proxy import RadioReport
from link.radio import LinkState, Radio, subsystem_rng
from link.transports import LockstepBus
from sim.firmware.lockstep import DT, MODE_NAMES, SKID_PARAMS, SPEEDUP, Lockstep
from sim.firmware.operator import FirmwareOperator
from sim.jams import Jams, radio_event
from sim.policies import COMPANION_POLICY, FAILSAFE_POLICIES
from sim.robots import make_robot
from sim.runner import TLOG_EPOCH_US
from sim.scenario import Scenario
from vehicle.companion.setup import NEEDS

_TLOG_STAMP = struct.Struct(">Q").pack
# per policy; the companion's is the backstop: Hold once a dead companion's keepalive stops (docs/architecture.md §11)
FS_ACTION: dict[str, int] = {"ardupilot-hold": 2, "ardupilot-rtl": 1, "ardupilot-smartrtl": 4, COMPANION_POLICY: 2}


def firmware_params(policy: str, lnk_timeout: float, max_speed: float) -> dict[str, float]:
    """What a firmware run sets on top of ArduPilot's own SITL rover defaults, and why:
    - the policy's failsafe: FS_GCS_ENABLE 1, FS_ACTION per policy, FS_GCS_TIMEOUT = the scenario's LNK_TIMEOUT
      (at least 2 s, the firmware's range), so it reacts to the same silence the native vehicle does;
    - FS_THR_ENABLE 0: nobody holds an RC transmitter here, and its radio failsafe would fire at once;
    - CRUISE_SPEED/CRUISE_THROTTLE matching the bridge's throttle scale (full throttle = the rover's top speed), so
      the speed controller's feed-forward is right from the start;
    - WP_RADIUS 1 m: a GUIDED position target counts as reached where the scripted operator moves on;
    - skid steering (SERVO1_FUNCTION 73, SERVO3_FUNCTION 74): the scenario's rover is a differential drive that
      turns on the spot, as the native vehicle's is, so only the autopilot differs between the two (as a car, the
      firmware had to drive forward to turn round and wedged itself in the 3.6 m culvert).
    For the companion the GCS failsafe is its backstop, not the link-loss policy: its keepalive is what the firmware
    hears, so FS_GCS_TIMEOUT is what ``returnlink companion --check`` asks for (2..5 s), and every other parameter
    on that list is set to the value ``--configure`` would set (``vehicle.companion.setup.NEEDS``), so the run
    starts from a firmware the companion's own check passes."""
    params = {"FS_GCS_ENABLE": 1, "FS_ACTION": FS_ACTION[policy], "FS_GCS_TIMEOUT": max(2.0, lnk_timeout),
              "FS_THR_ENABLE": 0, "CRUISE_SPEED": round(max_speed / 2, 3), "CRUISE_THROTTLE": 50, "WP_RADIUS": 1.0,
              **SKID_PARAMS}
    if policy == COMPANION_POLICY:
        for need in NEEDS:
            value = params.get(need.name, 0.0)  # ArduPilot's default of the others is 0
            params[need.name] = value if need.ok(value) else need.fix(value)
    return params


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


class FirmwareRun:
    """One scenario flown by the firmware. ``run()`` returns self with ``rows`` and the firmware's record (``link``);
    the firmware is stopped when the run ends, raises, or is interrupted."""

    kind = "ardurover"
    speedup = SPEEDUP  # the firmware's own pace; lockstep runs leave the pace to the bridge
    policies: tuple[str, ...] = FAILSAFE_POLICIES  # what this class flies (``companion.firmware_run`` picks)

    def __init__(self, scenario: Scenario, seed: int | None = None, policy: str = "ardupilot-smartrtl",
                 firmware: Path | None = None, progress: bool = False, duration: float | None = None,
                 log_path: Path | None = None) -> None:
        if policy not in self.policies:
            raise ValueError(f"policy {policy!r} is not one of {', '.join(self.policies)}")
        if firmware is None:
            raise ValueError("no firmware binary given")
        self.scenario = sc = scenario
        self.policy = policy
        self.seed = sc.seed if seed is None else seed
        self.duration = sc.duration if duration is None else duration
        self.progress = progress
        self.world = sc.world()
        x, y, yaw = sc.start
        self.robot = make_robot("rover", self.world, x, y, yaw, subsystem_rng(self.seed, "robot"))
        self.origin = (x, y)
        self.lnk_timeout = float(sc.params.get("LNK_TIMEOUT", 3.0))
        self.link = Lockstep(self.world, self.robot, firmware,
                             firmware_params(policy, self.lnk_timeout, self.robot.max_speed), self.speedup, log_path)
        self.radio = Radio(sc.radio, self.world.attenuation_db, self.seed)
        self.radio_report = RadioReport()
        self.bus = LockstepBus()
        self.stations = {s.name: Station(s.name, (s.x, s.y), s.power_dbm, s.name == sc.operator_station)
                         for s in sc.stations}
        self.op_station = self.stations[sc.operator_station]
        self.operator = self._make_operator(sc)
        self.op_station.operator = self.operator
        self.events = sorted(sc.events, key=lambda e: e.t)
        self.jams = Jams()
        self.t = 0.0
        self.heard: list[float] = []  # scenario times at which the firmware received a frame from the owner
        # per tick: (t, true x, true y, est x, est y, mode, link delivery, rssi, speed cmd, yaw rate cmd, armed,
        # collisions so far)
        self.rows: list[tuple] = []
        self.notes: list[str] = []
        self.tlog: list[bytes] = []  # the operator station's traffic, as ``sim.runner.Run`` keeps it
        self.wall = 0.0
        self.stopped = False
        self.next_radio_status = 0.0
        self.metrics: dict | None = None

    def _make_operator(self, sc: Scenario) -> FirmwareOperator:
        """The scripted operator: a person flying the firmware in GUIDED from the scenario's station."""
        return FirmwareOperator(sc.route, sc.resume_route, self.origin, sc.attempts,
                                sysid=sc.station(sc.operator_station).sysid)

    # ----- the loop ------------------------------------------------------------------------------------------
    def run(self) -> FirmwareRun:
        w0 = time.perf_counter()
        freeze = gc.get_freeze_count() == 0
        if freeze:
            gc.freeze()
        try:
            self.link.start()
            self._boot()
            self._loop()
        finally:
            if freeze:
                gc.unfreeze()
            self.link.close()
        self.wall = time.perf_counter() - w0
        if self.link.tap.version is None:
            self.link.tap.version = "ArduRover (version not reported)"
        return self

    def _boot(self) -> None:
        self.link.boot()

    def _loop(self) -> None:
        tty = sys.stderr.isatty()
        shown = [-1]
        boot = self.link.boot_s

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
                print(f"\r  [{bar}] {pct:3d}%  t={t:6.1f} s  {MODE_NAMES.get(self.link.tap.mode, '?'):<10}",
                      end="" if tty else "\n", file=sys.stderr, flush=True)

        while not self.stopped and self.t < self.duration - 1e-9:
            self.link.frames(self.link.t_fw + DT, tick)
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
        # the vehicle's frames out through the radio
        frames = self._vehicle_frames(t)
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
            self._vehicle_receive(data, src, t)
        self._vehicle_tick(t)
        if t >= self.next_radio_status:
            self.next_radio_status = t + 1.0
            self._radio_status(t)
        self._record(t, pos)

    # ----- the vehicle's side of the radio: the firmware's SERIAL0 itself -------------------------------------
    def _vehicle_frames(self, t: float) -> list[bytes]:
        """What the vehicle sends through the radio this tick: here everything the firmware said."""
        return self.link.drain(t)

    def _vehicle_receive(self, data: bytes, src: str, t: float) -> None:
        """A frame the radio delivered from station ``src``: here straight to the firmware."""
        if self.link.fw_addr is not None:
            self.link.send(data)
            if src == self.op_station.name:
                self.heard.append(t)

    def _vehicle_tick(self, t: float) -> None:
        """Whatever runs on the vehicle beside the firmware, once a tick after the radio delivered: here nothing."""

    def _radio_status(self, t: float) -> None:
        """Once a second: the operator's telemetry radio reports both ends' RSSI to its ground station, as a SiK
        radio would."""
        op = self.op_station
        if op.alive and op.state is not None and op.operator is not None:
            data = self.radio_report.frame(op.state, jammed=self._jammed(op.name, t))
            op.operator.feed(data, t)
            self._log_frame(data, t)

    def _log_frame(self, data: bytes, t: float) -> None:
        self.tlog.append(_TLOG_STAMP(TLOG_EPOCH_US + int(t * 1e6)) + data)

    def _jammed(self, station: str, t: float) -> bool:
        return self.jams.jammed(station, t)

    def _events(self, t: float) -> None:
        while self.events and self.events[0].t <= t + 1e-9:
            self._event(self.events.pop(0), t)

    def _event(self, ev, t: float) -> None:
        """One timed event of the scenario, due now."""
        st = self.stations.get(ev.station or self.scenario.operator_station)
        if radio_event(ev, st, self.jams, t):
            return
        if ev.action == "rtl" and st is not None and st.operator is not None:
            st.operator.request_rtl(t)
        elif ev.action == "stop":
            self.stopped = True
        else:
            # leases, claims and returnlink parameters mean nothing to the firmware: said, not faked
            self.notes.append(f"t={ev.t:g} s: event {ev.action!r} does not apply to the ArduPilot firmware")

    def _record(self, t: float, pos: tuple[float, float]) -> None:
        est = self.link.tap.estimate
        ex, ey = (self.origin[0] + est[0], self.origin[1] + est[1]) if est is not None else (math.nan, math.nan)
        op = self.op_station
        if op.state is None:
            link, rssi = 0.0, math.nan
        else:
            link = 0.0 if self._jammed(op.name, t) else op.state.delivery
            rssi = op.state.rssi_dbm
        mode = -1 if self.link.tap.mode is None else self.link.tap.mode
        self.rows.append((t, pos[0], pos[1], ex, ey, mode, link, rssi, *self.link.cmd, self.link.tap.armed,
                          self.world.collisions))

    # ----- reading the record --------------------------------------------------------------------------------
    @property
    def firmware_modes(self) -> list[dict]:
        return [{"t": round(t, 3), "mode": MODE_NAMES.get(m, str(m))} for t, m in self.link.tap.modes]

    def true_at(self, t: float) -> tuple[float, float]:
        k = min(len(self.rows) - 1, max(0, int(round(t / DT)) - 1))
        row = self.rows[k]
        return row[1], row[2]


__all__ = ["FS_ACTION", "FirmwareRun", "MODE_NAMES", "firmware_params"]
