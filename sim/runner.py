"""``returnlink sim run``: one scenario in lockstep, as fast as the machine allows, whatever flies it.

One loop for every plant (``sim.plants``: returnlink's vehicle on a pymunk robot, the ArduPilot firmware over its
JSON backend, the firmware with returnlink companion beside it, PX4 over its HIL link). Every tick: radio
deliveries due -> ground stations parse real MAVLink bytes -> timed events and the scripted operator -> the plant
hears what the radio delivered to it and ticks -> every frame either side sent goes through the radio model
(per-packet loss and latency, both directions) onto a lockstep bus -> RADIO_STATUS -> the record. (The autopilots
hear and tick after the stations' radio leg instead: ``Plant.hears_last``.) Nothing reads the wall clock except the
real-time-factor figure, so the same scenario and seed give the same metrics.

Every random draw comes from a stream of its own subsystem, derived from the seed by name (the robot, the
sensors, the shadowing field, each direction of each station's radio link): a run flown under another link-loss
policy (``policy=``, docs/architecture.md §9), or by another plant, sees the same world, noise and packet fates,
and so the same trace, until the first COMMS_LOST, where only the policy differs.
"""

from __future__ import annotations

import gc
import json
import math
import struct
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from link.proxy import RadioReport
from link.radio import LinkState, Radio
from link.transports import LockstepBus
from sim.jams import Jams, radio_event
from sim.lease_record import LeaseRecord
from sim.plants import Plant
from sim.plants import registry as plants_registry
from sim.plants.native import TICK_RATE
from sim.registry import DEFAULT_POLICY
from sim.scenario import Scenario
from vehicle.core import DT
from vehicle.lease import Holder
from vehicle.lease_terms import State
from vehicle.port import Status

# A lockstep run has no wall-clock time of its own: its .tlog is stamped from 2026-01-01 00:00:00 UTC + sim time
# (1970, the UNIX epoch itself, made MAVProxy and QGroundControl show a log from before MAVLink existed).
TLOG_EPOCH_US = 1_767_225_600 * 1_000_000
_TLOG_STAMP = struct.Struct(">Q").pack


@dataclass
class StationSim:
    """One ground station in the simulation, whatever the plant: its antenna, whether it is running, its channel
    this tick, the software it runs (``gs``: what it hears and sends, or None for a station nobody runs; the
    scripted ``operator`` on it, or None) and whether its traffic goes to the .tlog (the operator's)."""

    name: str
    gs: Any
    antenna: tuple[float, float]
    power_dbm: float
    alive: bool
    state: LinkState | None = None
    operator: Any = None
    logged: bool = False
    # the two directions of its radio link, named once: (source, destination) lane and fate stream
    down: tuple[tuple[str, str], str] = field(init=False)
    up: tuple[tuple[str, str], str] = field(init=False)
    # its live queue on the lockstep bus (``LockstepBus.inbox``): the tick looks at its head before receiving
    inbox: list = field(init=False, default_factory=list, repr=False)

    def __post_init__(self) -> None:
        self.down = (("vehicle", self.name), f"downlink.{self.name}")
        self.up = ((self.name, "vehicle"), f"uplink.{self.name}")


@contextmanager
def frozen() -> Iterator[None]:
    """The objects alive before a run's loop (the libraries, the dialect, the scenario: some 80,000) frozen out of
    garbage collection while it runs, as none of them becomes garbage there: a full collection during the run then
    scans only what the run made, instead of spending tens of milliseconds on them each time. They are handed back
    to the collector afterwards, unless the caller had frozen objects of its own."""
    freeze = gc.get_freeze_count() == 0
    if freeze:
        gc.freeze()
    try:
        yield
    finally:
        if freeze:
            gc.unfreeze()


def plant_for(vehicle: str, policy: str) -> type:
    """The plant that flies ``policy`` on ``vehicle``, from the plant registry (``sim.plants.registry``; each
    plant refuses a policy it cannot fly, saying why)."""
    return plants_registry.plant_for(vehicle, policy)


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
    """One scenario flown by one plant (``plant``: chosen by ``plant_for`` from the vehicle and the policy, or
    given; ``options`` go to it, e.g. the firmware's ``firmware=PATH`` and ``log_path``). ``run()`` flies it and
    returns self; the record (``trace``, the lease record of ``sim.lease_record``, ``tlog``) and ``metrics`` are
    read from it afterwards. ``step()`` moves a plant without a clock of its own (the native one) by one tick, for
    tests that drive the ticks by hand."""

    def __init__(self, scenario: Scenario, vehicle: str | None = None, seed: int | None = None,
                 progress: bool = False, duration: float | None = None, policy: str = DEFAULT_POLICY,
                 plant: type | None = None, **options) -> None:
        self.scenario = sc = scenario
        self.policy = policy
        self.seed = sc.seed if seed is None else seed
        kind = vehicle or sc.vehicle
        self.plant: Plant = (plant or plant_for(kind, policy))(sc, kind, self.seed, policy, **options)
        self.kind = self.plant.kind
        self.world = self.plant.world
        self.robot = self.plant.robot
        self.frame_offset = self.plant.frame_offset
        self.radio = Radio(sc.radio, self.world.attenuation_db, self.seed)
        self.radio_report = RadioReport()
        self.bus = LockstepBus()
        self.stations: dict[str, StationSim] = {}
        for s in sc.stations:
            gs, operator = self.plant.station(s, s.name == sc.operator_station)
            self.stations[s.name] = StationSim(s.name, gs, (s.x, s.y), s.power_dbm, s.name == sc.operator_station,
                                               operator=operator, logged=s.name == sc.operator_station)
        self._station_list = list(self.stations.values())  # the tick walks it four times
        self._inbox = self.bus.inbox("vehicle")
        for st in self._station_list:
            st.inbox = self.bus.inbox(st.name)
        self._operator = self.stations[sc.operator_station]
        self.events = sorted(sc.events, key=lambda e: e.t)
        self.jams = Jams()
        self.t = 0.0
        self.ticks = 0
        self.duration = sc.duration if duration is None else duration
        self.trace = Trace()
        self.tlog: list[bytes] = []
        self.notes: list[str] = []  # events that do not apply to the plant, said in the summary rather than faked
        self.progress = progress
        self.wall = 0.0
        self.stopped = False
        self.metrics: dict | None = None
        self.next_radio_status = 0.0
        # the record's view of the ticks (``sim.lease_record``): rows that start (t, true x, true y, est x, est y)
        self._own_rows = self.plant.rows is not None
        self._rows = self.plant.rows if self._own_rows else self.trace.rows
        # the vehicle's estimate is in its own frame: moved into the true one unless the two are the same
        self._shift = None if self.frame_offset == (0.0, 0.0) else self.frame_offset
        self._start_record()

    @property
    def vehicle(self):
        """returnlink's vehicle aboard the plant (None: the firmware alone, or a companion not booted yet)."""
        return self.plant.vehicle

    @property
    def contingency(self):
        """The link-loss baseline the plant's vehicle flies instead of the return plan (``sim.policies``), or None."""
        return self.plant.contingency

    @property
    def audit_stale(self) -> int:
        """Actuations the run's own audits found outside the lease last announced: a returnlink vehicle's teleop
        setpoints (``_audit``), and whatever the plant audits of its own (the companion's router)."""
        return self.stale_setpoints + self.plant.stale

    # ----- the loop ------------------------------------------------------------------------------------------
    def run(self) -> Run:
        """Every tick to the end (or a ``stop`` event), with the run's objects frozen out of garbage collection
        (``frozen``); whatever the plant runs outside this process is stopped when the run ends, raises, or is
        interrupted."""
        w0 = time.perf_counter()
        with frozen():
            try:
                self._boot()
                self._loop()
            finally:
                self.plant.close()
        self.wall = time.perf_counter() - w0
        self._close_block()
        return self

    def _boot(self) -> None:
        """The plant to scenario time 0."""
        self.plant.start()

    def _loop(self) -> None:
        """The ticks, paced by the plant, with a progress bar when asked (redrawn on a terminal, a few lines in a
        log)."""
        if self.progress:
            self._shown, self._tty = -1, sys.stderr.isatty()
            self._ticks_due = max(1, int(round(self.duration / DT)))
        self.plant.pace(self._paced, self.duration)
        if self.progress and self._tty:
            print(file=sys.stderr)

    def _paced(self, t: float) -> bool:
        """The tick at ``t``; False once the run stops."""
        self._tick(t)
        if self.stopped:
            return False
        if self.progress and (pct := 100 * self.ticks // self._ticks_due) != self._shown \
                and pct % (2 if self._tty else 25) == 0:
            self._shown = pct
            bar = "#" * (pct // 4) + "." * (25 - pct // 4)
            print(f"\r  [{bar}] {pct:3d}%  t={t:6.1f} s{self.plant.status()}", end="" if self._tty else "\n",
                  file=sys.stderr, flush=True)
        return True

    def step(self) -> None:
        """The next tick of a plant without a clock of its own."""
        self._tick((self.ticks + 1) / TICK_RATE)

    def _tick(self, t: float) -> None:
        """One tick, in the order of the module's docstring. Work nothing waits for is skipped (an empty queue, a
        dead station, a timed event not due yet), never reordered: the radio draws each packet's fate in the same
        order as ever."""
        self.ticks += 1
        self.t = t
        self._deliver(t)
        if self.events and self.events[0].t <= t + 1e-9:
            self._events(t)
        for st in self._station_list:
            if st.alive and st.operator is not None:
                st.operator.step(t)
        plant = self.plant
        hears_last = plant.hears_last
        if not hears_last:
            self._tick_vehicle(t)
        pos = self.robot.pose[:2]
        radio = self.radio
        for st in self._station_list:
            st.state = radio.link(st.antenna, st.power_dbm, pos) if st.alive else None
        self._downlink(plant.frames(t), t)
        self._uplink(t)
        if hears_last:
            self._tick_vehicle(t)
        if t >= self.next_radio_status:
            self.next_radio_status = t + 1.0
            self._radio_status(t)
        self._record(t, pos)

    def _deliver(self, t: float) -> None:
        """What the radio delivers by ``t`` to every station (a dead one, or one nobody runs, drops it). A queue is
        received from only when its head is due (most ticks nothing is: a call saved)."""
        for st in self._station_list:
            inbox = st.inbox
            if not inbox or inbox[0][0] > t:
                continue
            for data, _src in self.bus.receive(st.name, t):
                if st.alive and st.gs is not None:
                    st.gs.feed(data, t)
                    if st.logged:
                        self._log_frame(data, t)

    def _tick_vehicle(self, t: float) -> None:
        """What the radio delivered to the vehicle, then its tick, and what the record needs of that tick: when the
        owner's link came back, and each new lease event (the lease the audit expects, the losses and the
        regains)."""
        plant = self.plant
        inbox = self._inbox
        if inbox and inbox[0][0] <= t:
            plant.receive(self.bus.receive("vehicle", t), t)
        v = plant.vehicle
        if v is None:
            plant.tick(t)
            return
        before = self._vehicle_state(v)
        plant.tick(t)
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
            if not st.alive or st.gs is None:
                continue
            sent = st.gs.tick(t)
            if not sent:
                continue
            if st.logged:
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
        """The operator's telemetry radio reports both ends' RSSI, as a SiK radio would: the ground end to its
        station, the vehicle end to the plant (nothing while jammed: the radio hears nothing then)."""
        op = self._operator
        if not op.alive or op.state is None:
            return
        jammed = self._jammed(op.name, t)
        if not jammed:
            self.plant.radio_status(op.state, t)
        data = self.radio_report.frame(op.state, jammed=jammed)
        op.gs.feed(data, t)
        self._log_frame(data, t)

    def _log_frame(self, data: bytes, t: float) -> None:
        self.tlog.append(_TLOG_STAMP(TLOG_EPOCH_US + int(t * 1e6)) + data)

    # ----- timed events --------------------------------------------------------------------------------------
    def _events(self, t: float) -> None:
        """The events due: ``stop`` and the radio's own (``sim.jams``) here; what one does to a station's software
        is the plant's (``Plant.event``), and one that does not apply to it is noted for the summary."""
        while self.events and self.events[0].t <= t + 1e-9:
            ev = self.events.pop(0)
            st = self.stations.get(ev.station or self.scenario.operator_station)
            if ev.action == "stop":
                self.stopped = True
            elif not radio_event(ev, st, self.jams, t) or ev.action == "revive_gcs":
                note = self.plant.event(ev, st, t)
                if note:
                    self.notes.append(note)

    # ----- recording -----------------------------------------------------------------------------------------
    def _record(self, t: float, pos: tuple[float, float]) -> None:
        """The tick's rows: the plant's own, and for a plant that flies returnlink's leases the trace row and the
        lease record (the block under way, the audit)."""
        op = self._operator
        state = op.state
        if state is None:
            link, rssi = 0.0, math.nan
        else:
            link = 0.0 if self.jams and self._jammed(op.name, t) else state.delivery
            rssi = state.rssi_dbm
        plant = self.plant
        if self._own_rows:
            plant.record(t, pos, link, rssi)
        if not plant.leases:
            return
        v = plant.vehicle
        if v is None:  # not booted yet (the companion waits for the autopilot's first estimate)
            ex, ey = plant.estimate()
            self.trace.rows.append((t, pos[0], pos[1], ex, ey, 0, -1, State.NO_OWNER, link, rssi, False, 0.0, 0.0))
            return
        s = v.status()  # (the snapshot of this tick: the endpoint's telemetry took it already, most ticks)
        p = s.pose
        shift = self._shift
        if shift is None:
            ex, ey = p.x, p.y
        else:
            ex, ey = shift[0] + p.x, shift[1] + p.y
        cur = s.book.current
        if cur is None:
            holder, index, returning = 0, -1, False
        else:
            h = cur.holder
            holder, index, returning = int(h), cur.index, h is Holder.RETURN_SERVICE
        speed, yaw_rate = s.command_out
        self.trace.rows.append((t, pos[0], pos[1], ex, ey, holder, index, s.state, link, rssi, s.link_good,
                                speed, yaw_rate))
        if s.setpoint is not None:
            self._audit(s)
        self._track_block(s, t, pos, cur, returning)

    def _audit(self, s: Status) -> None:
        """An independent check of a returnlink vehicle's stale-command guard (``s``: its snapshot of this tick): a
        teleop setpoint that moved the robot this tick must carry the lease the vehicle last announced as current
        (LEASE_EVENT) and come from the owner. (The companion runs without teleop: its guard is its router, which
        its plant audits.)"""
        sp = s.setpoint
        if sp is None or s.command_out == (0.0, 0.0) or self.announced is None:
            return
        if (sp.lease.epoch, sp.lease.path[0]) != self.announced or sp.sender != s.book.owner:
            self.stale_setpoints += 1


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
