"""``returnlink sim run``: one scenario in lockstep, as fast as the machine allows.

Every tick: radio deliveries due -> ground stations and vehicle parse real MAVLink bytes -> timed events and the
scripted operator -> the vehicle loop -> physics -> every frame either side sent goes through the radio model
(per-packet loss and latency, both directions) onto a lockstep bus. Nothing reads the wall clock except the
real-time-factor figure, so the same scenario and seed give the same metrics.

Every random draw comes from a stream of its own subsystem, derived from the seed by name (the robot, the
sensors, the shadowing field, each direction of each station's radio link): a run flown under another link-loss
policy (``policy=``, docs/architecture.md §9) sees the same world, noise and packet fates, and so the same trace, until
the first COMMS_LOST, where only the policy differs.
"""

from __future__ import annotations

import gc
import json
import math
import struct
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from gcs.plans import from_plan_items
from gcs.station import GroundStation
from link.proxy import RadioReport
from link.radio import LinkState, Radio
from link.transports import LockstepBus
from sim.driver import simulated_vehicle
from sim.jams import Jams, radio_event
from sim.lease_record import LeaseRecord
from sim.operator import Operator
from sim.policies import DEFAULT_POLICY, check_policy, make_policy
from sim.scenario import Scenario
from vehicle.app import DT
from vehicle.lease import Holder

# A lockstep run has no wall-clock time of its own: its .tlog is stamped from 2026-01-01 00:00:00 UTC + sim time
# (1970, the UNIX epoch itself, made MAVProxy and QGroundControl show a log from before MAVLink existed).
TLOG_EPOCH_US = 1_767_225_600 * 1_000_000
_TLOG_STAMP = struct.Struct(">Q").pack
# Tick k is at k / TICK_RATE s: the double nearest k * DT, which is what rounding the running sum to 9 decimals
# every tick gave (for DT = 1/50 s the sum strays from k / 50 by far less than 1e-9 for days of ticks), at the
# cost of a division instead of a ``round``
TICK_RATE = round(1 / DT)

@dataclass
class StationSim:
    """One ground station in the simulation: its library instance, antenna and whether it is running."""

    name: str
    gs: GroundStation
    antenna: tuple[float, float]
    power_dbm: float
    alive: bool
    state: LinkState | None = None
    operator: Operator | None = None
    # the two directions of its radio link, named once: (source, destination) lane and fate stream
    down: tuple[tuple[str, str], str] = field(init=False)
    up: tuple[tuple[str, str], str] = field(init=False)
    # its live queue on the lockstep bus (``LockstepBus.inbox``): the tick looks at its head before receiving
    inbox: list = field(init=False, default_factory=list, repr=False)

    def __post_init__(self) -> None:
        self.down = (("vehicle", self.name), f"downlink.{self.name}")
        self.up = ((self.name, "vehicle"), f"uplink.{self.name}")


def _column(name: str) -> property:
    """A read-only ``Trace`` attribute: the list of one column over every tick recorded so far."""
    return property(lambda trace: trace.column(name))


class Trace:
    """Per-tick record for metrics and plots.

    The tick appends one row of plain numbers (one append instead of ten); the named columns (``t``, ``true``,
    ``est``, ...) are built from the rows when first read after new ticks. A row holds only floats, ints and
    bools, no tuple and no object of the run (a pose, a lease, a channel state), so the garbage collector stops
    tracking it at its first collection: rows kept alive by the thousand cost the collector nothing after."""

    def __init__(self) -> None:
        # (t, true x, true y, estimated x, estimated y, holder, index, vehicle state, delivery to the operator's
        # station, its RSSI, owner heard, commanded speed, commanded yaw rate)
        self.rows: list[tuple] = []
        self._built = -1
        self._columns: dict[str, list] = {}

    def column(self, name: str) -> list:
        if self._built != len(self.rows):
            self._build()
        return self._columns[name]

    def _build(self) -> None:
        columns = [list(c) for c in zip(*self.rows, strict=True)] or [[] for _ in range(13)]
        t, x, y, ex, ey, holder, index, state, link, rssi, heard, speed, yaw_rate = columns
        self._columns = {"t": t, "true": list(zip(x, y, strict=True)), "est": list(zip(ex, ey, strict=True)),
                         "holder": holder, "index": index, "state": state, "link": link, "rssi": rssi,
                         "heard": heard, "cmd": list(zip(speed, yaw_rate, strict=True))}
        self._built = len(self.rows)

    t = _column("t")
    true = _column("true")  # the robot's true (x, y)
    est = _column("est")  # the estimator's (x, y)
    holder = _column("holder")
    index = _column("index")
    state = _column("state")
    link = _column("link")  # delivery probability to the operator's station (0 while jammed)
    rssi = _column("rssi")
    heard = _column("heard")  # owner heard within LNK_GOOD_S (the vehicle's view)
    cmd = _column("cmd")  # what the vehicle commanded the robot


class Run(LeaseRecord):
    frame_offset = (0.0, 0.0)  # the vehicle's frame in the true one: the same, its estimator starts at its true pose

    def __init__(self, scenario: Scenario, vehicle: str | None = None, seed: int | None = None,
                 progress: bool = False, duration: float | None = None, policy: str = DEFAULT_POLICY) -> None:
        self.scenario = sc = scenario
        self.policy = check_policy(policy)
        self.kind = vehicle or sc.vehicle
        self.seed = sc.seed if seed is None else seed
        self.driver, self.vehicle, self.endpoint = simulated_vehicle(sc, self.kind, self.seed,
                                                                     contingency=make_policy(self.policy))
        self.world = self.driver.world
        self.robot = self.driver.robot
        self.radio = Radio(sc.radio, self.world.attenuation_db, self.seed)
        self.radio_report = RadioReport()
        self.bus = LockstepBus()
        self.stations: dict[str, StationSim] = {}
        for s in sc.stations:
            gs = GroundStation(s.sysid, 190)
            self.stations[s.name] = StationSim(s.name, gs, (s.x, s.y), s.power_dbm, s.name == sc.operator_station)
        self._station_list = list(self.stations.values())  # the tick walks it four times
        self._inbox = self.bus.inbox("vehicle")
        for st in self._station_list:
            st.inbox = self.bus.inbox(st.name)
        self._operator = op = self.stations[sc.operator_station]
        op.operator = Operator(op.gs, sc.route, sc.resume_route, from_plan_items(sc.plan), sc.teleop,
                                   attempts=sc.attempts, rejoin=sc.rejoin)
        self.events = sorted(sc.events, key=lambda e: e.t)
        self.jams = Jams()
        self.t = 0.0
        self.ticks = 0
        self.duration = sc.duration if duration is None else duration
        self.trace = Trace()
        self.tlog: list[bytes] = []
        self.progress = progress
        self.wall = 0.0
        self.stopped = False
        self.metrics: dict | None = None
        self.next_radio_status = 0.0
        self._rows = self.trace.rows  # the record's view of the ticks (``sim.lease_record``)
        self._start_record()

    # ----- the loop ------------------------------------------------------------------------------------------
    def run(self) -> Run:
        """Every tick to the end (or a ``stop`` event).

        The objects alive before the loop (the libraries, the dialect, the scenario: some 80,000) are frozen out
        of garbage collection while it runs, as none of them becomes garbage there: a full collection during the
        run then scans only what the run made, instead of spending tens of milliseconds on them each time. They
        are handed back to the collector afterwards, unless the caller had frozen objects of its own."""
        w0 = time.perf_counter()
        n = int(round(self.duration / DT))
        shown = -1
        tty = sys.stderr.isatty()
        step = 2 if tty else 25  # a redrawn bar on a terminal, a few lines in a log
        freeze = gc.get_freeze_count() == 0
        if freeze:
            gc.freeze()
        try:
            for k in range(n):
                self.step()
                if self.stopped:
                    break
                if self.progress and (pct := 100 * (k + 1) // n) != shown and pct % step == 0:
                    shown = pct
                    bar = "#" * (pct // 4) + "." * (25 - pct // 4)
                    print(f"\r  [{bar}] {pct:3d}%  t={self.t:6.1f} s", end="" if tty else "\n", file=sys.stderr,
                          flush=True)
        finally:
            if freeze:
                gc.unfreeze()
        if self.progress and tty:
            print(file=sys.stderr)
        self.wall = time.perf_counter() - w0
        self._close_block()
        return self

    def step(self) -> None:
        """One tick, in the order of the module's docstring. Work nothing waits for is skipped (an empty queue, a
        dead station, a timed event not due yet), never reordered: the radio draws each packet's fate in the same
        order as ever."""
        self.ticks += 1
        self.t = t = self.ticks / TICK_RATE
        self._deliver(t)
        if self.events and self.events[0].t <= t + 1e-9:
            self._events(t)
        for st in self._station_list:
            if st.alive and st.operator is not None:
                st.operator.step(t)
        self._tick_vehicle(t)
        self.driver.advance(DT)
        pos = self.robot.pose[:2]
        radio = self.radio
        for st in self._station_list:
            st.state = radio.link(st.antenna, st.power_dbm, pos) if st.alive else None
        self._downlink(self.endpoint.tick(t), t)
        self._uplink(t)
        if t >= self.next_radio_status:
            self.next_radio_status = t + 1.0
            self._radio_status(t)
        self._record(t, pos)

    def _deliver(self, t: float) -> None:
        """What the radio delivers by ``t``: to the vehicle's endpoint, and to every station (a dead one drops it).
        A queue is received from only when its head is due (most ticks nothing is: a call saved)."""
        inbox = self._inbox
        if inbox and inbox[0][0] <= t:
            for data, _src in self.bus.receive("vehicle", t):
                self.endpoint.receive(data, t)
        for st in self._station_list:
            inbox = st.inbox
            if not inbox or inbox[0][0] > t:
                continue
            for data, _src in self.bus.receive(st.name, t):
                if st.alive:
                    st.gs.feed(data, t)
                    if st.operator is not None:
                        self._log_frame(data, t)

    def _tick_vehicle(self, t: float) -> None:
        """The vehicle loop's tick, and what the metrics need of it: when the owner's link came back, and each
        new lease event (the lease the runner's own audit expects, the losses and the regains)."""
        v = self.vehicle
        before = self._vehicle_state(v)
        v.tick(t)
        self._vehicle_ticked(v, t, before)

    def _downlink(self, frames: list[bytes], t: float) -> None:
        """The vehicle's frames through the radio to every station in range; a station out of range or jammed
        hears nothing, and its fates are not drawn."""
        if not frames:
            return
        radio, bus = self.radio, self.bus
        live = [st for st in self._station_list
                if st.state is not None and not (self.jams and self._jammed(st.name, t))]
        for data in frames:
            for st in live:
                lane, stream = st.down
                at = radio.arrival(st.state, t, lane, stream)
                if at is not None:
                    bus.send("vehicle", st.name, data, at)

    def _uplink(self, t: float) -> None:
        """Every live station's tick: what it sends goes to the .tlog (the operator's) and through the radio to the
        vehicle, unless out of range or jammed."""
        radio, bus = self.radio, self.bus
        for st in self._station_list:
            if not st.alive:
                continue
            sent = st.gs.tick(t)
            if not sent:
                continue
            if st.operator is not None:
                for data in sent:
                    self._log_frame(data, t)
            if st.state is None or (self.jams and self._jammed(st.name, t)):
                continue
            lane, stream = st.up
            for data in sent:
                at = radio.arrival(st.state, t, lane, stream)
                if at is not None:
                    bus.send(st.name, "vehicle", data, at)

    def _jammed(self, station: str, t: float) -> bool:
        return self.jams.jammed(station, t)

    def _radio_status(self, t: float) -> None:
        """The operator's telemetry radio reports both ends' RSSI, as a SiK radio would."""
        op = self._operator
        if not op.alive or op.state is None:
            return
        jammed = self._jammed(op.name, t)
        if not jammed:
            # the vehicle's radio measures the same channel: its RSSI goes on the vehicle's link map
            self.vehicle.radio_rssi(op.state.rssi_dbm)
        data = self.radio_report.frame(op.state, jammed=jammed)
        op.gs.feed(data, t)
        self._log_frame(data, t)

    def _log_frame(self, data: bytes, t: float) -> None:
        self.tlog.append(_TLOG_STAMP(TLOG_EPOCH_US + int(t * 1e6)) + data)

    # ----- timed events --------------------------------------------------------------------------------------
    def _events(self, t: float) -> None:
        while self.events and self.events[0].t <= t + 1e-9:
            ev = self.events.pop(0)
            name = ev.station or self.scenario.operator_station
            st = self.stations.get(name)
            if radio_event(ev, st, self.jams, t):
                if ev.action == "revive_gcs" and st is not None:
                    # a station coming back resumes what it was doing: its stale lease and its old stream
                    st.gs.t = t
                    if st.gs.teleop is None:
                        st.gs.drive_velocity(0.5, 0.0)
            elif ev.action == "takeover" and st is not None:
                st.alive = True
                st.gs.acquire(allow_takeover=False)
            elif ev.action == "rtl" and st is not None:
                st.gs.rtl()
            elif ev.action == "claim" and st is not None:
                st.gs.claim(-1)
            elif ev.action == "param" and st is not None:
                st.gs.param_set(ev.name, ev.value)
            elif ev.action == "stop":
                self.stopped = True

    # ----- recording -----------------------------------------------------------------------------------------
    def _record(self, t: float, pos: tuple[float, float]) -> None:
        v, tr = self.vehicle, self.trace
        p = v.estimator.pose
        cur = v.book.current
        if cur is None:
            holder, index, returning = 0, -1, False
        else:
            h = cur.holder
            holder, index, returning = int(h), cur.index, h is Holder.RETURN_SERVICE
        op = self._operator
        state = op.state
        if state is None:
            link, rssi = 0.0, math.nan
        else:
            link = 0.0 if self.jams and self._jammed(op.name, t) else state.delivery
            rssi = state.rssi_dbm
        speed, yaw_rate = v.command_out
        tr.rows.append((t, pos[0], pos[1], p.x, p.y, holder, index, v.state(), link, rssi, v.link_is_good, speed,
                        yaw_rate))
        if v.setpoint is not None:
            self._audit(v)
        self._track_block(v, t, pos, cur, returning)

    def _audit(self, v) -> None:
        """An independent check of the stale-command guard: a teleop setpoint that moved the robot this tick must
        carry the lease the vehicle last announced as current (LEASE_EVENT) and come from the owner."""
        sp = v.setpoint
        if sp is None or v.command_out == (0.0, 0.0) or self.announced is None:
            return
        if (sp.lease.epoch, sp.lease.path[0]) != self.announced or sp.sender != v.book.owner:
            self.audit_stale += 1


def write_tlog(run: Run, path: Path) -> Path:
    """The operator station's traffic as a .tlog: each frame after its big-endian µs UNIX time, here the fixed
    epoch ``TLOG_EPOCH_US`` plus simulated time, so replay tools show a real date and the same run gives the same
    bytes."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"".join(run.tlog))
    return path


def write_metrics(metrics: dict, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(metrics, indent=2) + "\n", encoding="utf-8")
    return path
