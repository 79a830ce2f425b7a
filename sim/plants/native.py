"""The native plant: returnlink's own vehicle (booted by ``vehicle.core.boot_core``, behind its MAVLink endpoint) on
the scenario's pymunk robot, its sensors and a link-loss policy (``sim.policies``), for ``sim.runner.Run``.

It has no clock of its own: tick k is at k / TICK_RATE, as fast as the machine allows. In each tick the vehicle
first reads what the radio delivered, ticks, and the physics steps; the loop's radio then carries the frames of the
pose just reached. Its stations run the ground-station library (``gcs.station.GroundStation``), the operator's with
the scripted operator (``sim.operator.Operator``) on it.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Hashable
from pathlib import Path

from gcs.plans import from_plan_items
from gcs.station import GroundStation
from link.radio import LinkState
from sim import registry
from sim.compare import EXACT
from sim.driver import simulated_vehicle
from sim.metrics import lease_figures
from sim.operator import Operator
from sim.policies import check_policy, make_policy
from sim.scenario import Event, Scenario, Station
from sim.summary import summary
from vehicle.core import DT

# Tick k is at k / TICK_RATE s: the double nearest k * DT, which is what rounding the running sum to 9 decimals
# every tick gave (for DT = 1/50 s the sum strays from k / 50 by far less than 1e-9 for days of ticks), at the
# cost of a division instead of a ``round``
TICK_RATE = round(1 / DT)


class NativePlant:
    """returnlink's vehicle on a pymunk robot (see the module docstring). ``vehicle``, ``endpoint`` and ``driver``
    are the very objects a robot's companion computer would run, with the simulated robot as their driver."""

    leases = True
    hears_last = False
    rows = None  # the loop's trace is the whole record
    frame_offset = (0.0, 0.0)  # the vehicle's frame is the true one: its estimator starts at its true pose
    stale = 0  # no guard of its own beside the vehicle's, which the loop audits
    repeatability = EXACT  # deterministic: the same scenario and seed give the same metrics, bit for bit
    policies: tuple[str, ...] = registry.NATIVE_PLANT.policies  # what this plant flies (its kind: the robot's)

    def __init__(self, scenario: Scenario, kind: str, seed: int, policy: str, param_file: Path | None = None,
                 boot_epoch: int | None = None, on_epoch: Callable[[int], str | None] | None = None,
                 **endpoint_options) -> None:
        """``param_file``, ``boot_epoch``, ``on_epoch`` and ``endpoint_options`` (a key, a signing clock): what a
        served vehicle boots with and keeps (``sim.serve.served_boot``); a lockstep run gives none of them."""
        self.scenario = scenario
        self.kind = kind
        self.contingency = make_policy(check_policy(policy))  # None: the return plan flies
        self.driver, self.vehicle, self.endpoint = simulated_vehicle(scenario, kind, seed, param_file, boot_epoch,
                                                                     contingency=self.contingency, on_epoch=on_epoch,
                                                                     **endpoint_options)
        self.world = self.driver.world
        self.robot = self.driver.robot
        # called every tick: bound once (the physics step's three calls are ``SimDriver.advance``'s, made here so
        # that the plant's tick costs the loop no more calls than the vehicle's tick and that step did)
        self.frames: Callable[[float], list[bytes]] = self.endpoint.tick
        self._vehicle_tick = self.vehicle.tick
        self._before_step = self.robot.before_step
        self._world_step = self.world.step
        self._after_step = self.robot.after_step

    # ----- the scenario around it ----------------------------------------------------------------------------
    def station(self, spec: Station, operator: bool) -> tuple[GroundStation, Operator | None]:
        """Every station runs the ground-station library; the operator's carries the scripted operator."""
        gs = GroundStation(spec.sysid, 190)
        if not operator:
            return gs, None
        sc = self.scenario
        return gs, Operator(gs, sc.route, sc.resume_route, from_plan_items(sc.plan), sc.teleop, attempts=sc.attempts,
                            rejoin=sc.rejoin)

    def event(self, ev: Event, st, t: float) -> str | None:
        """A station takes over, asks for a return, claims, sets a parameter; one coming back resumes what it was
        doing (its stale lease and its old stream)."""
        if st is None:
            return None
        gs = st.gs
        if ev.action == "revive_gcs":
            gs.t = t
            if gs.teleop is None:
                gs.drive_velocity(0.5, 0.0)
        elif ev.action == "takeover":
            st.alive = True
            gs.acquire(allow_takeover=False)
        elif ev.action == "rtl":
            gs.rtl()
        elif ev.action == "claim":
            gs.claim(-1)
        elif ev.action == "param":
            gs.param_set(ev.name, ev.value)
        return None

    # ----- time ----------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Nothing to start: the vehicle booted when it was made."""

    def pace(self, tick: Callable[[float], bool], duration: float) -> None:
        """Tick after tick, at once (a real-time loop waits in ``tick``); with no end when ``duration`` is
        infinite."""
        ticks = range(1, int(round(duration / DT)) + 1) if math.isfinite(duration) else itertools.count(1)
        for k in ticks:
            if not tick(k / TICK_RATE):
                return

    def close(self) -> None:
        """The signing timestamp to disk, if the vehicle signs with a kept key (nothing runs outside this
        process)."""
        self.endpoint.close()

    # ----- one tick ------------------------------------------------------------------------------------------
    def receive(self, frames: list[tuple[bytes, Hashable]], t: float) -> None:
        """Each frame with where it came from (a station's name, or a UDP address when served), which the
        endpoint remembers per sender so a transport can keep the owner's (``pinned``)."""
        receive = self.endpoint.receive
        for data, src in frames:
            receive(data, t, src)

    def replies(self) -> list[bytes]:
        """The endpoint's answers to what it received since its tick, without a tick."""
        return self.endpoint.replies()

    def pinned(self) -> list[Hashable]:
        return self.endpoint.pinned()

    def tick(self, t: float) -> None:
        """The vehicle loop's tick, then one physics step of DT: the robot pushes, pymunk steps, the robot reads
        where it went (``SimDriver.advance``)."""
        self._vehicle_tick(t)
        self._before_step(DT)
        self._world_step(DT)
        self._after_step(DT)

    def radio_status(self, state: LinkState, t: float) -> None:
        """The vehicle's radio measures the operator's channel: its RSSI goes on the vehicle's link map."""
        self.vehicle.radio_rssi(state.rssi_dbm)

    # ----- the record: the loop's trace holds all of it -------------------------------------------------------
    def estimate(self) -> tuple[float, float]:
        p = self.vehicle.status().pose
        return p.x, p.y

    def record(self, t: float, pos: tuple[float, float], link: float, rssi: float) -> None:
        """No row of its own (``rows`` is None: never called)."""

    def status(self) -> str:
        """The mode the vehicle shows (its heartbeat's custom_mode) and who owns it."""
        return f"  state {self.endpoint.custom_mode():#010x}  owner {self.vehicle.status().book.owner}"

    def started(self) -> str:
        return ""

    # ----- the figures ---------------------------------------------------------------------------------------
    def figures(self, run) -> dict:
        return lease_figures(run)

    def summary(self, run, m: dict) -> str:
        return summary(run, m)

    @staticmethod
    def pictures(run, out: Path) -> list[Path]:
        """trajectory.png and timeline.png of the leases (``sim.report``); matplotlib is imported only when plots
        are drawn (about 0.4 CPU-s)."""
        from sim import report

        return [report.trajectory(run, out / "trajectory.png"), report.timeline(run, out / "timeline.png")]

