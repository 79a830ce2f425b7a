"""returnlink companion beside an autopilot, as a plant's half: what the ArduPilot companion plant
(``sim.plants.companion``) and the PX4 one (``sim.plants.px4_companion``) share, written once.

The companion (``vehicle.companion.app.Companion``, the object ``returnlink companion`` runs on a robot) sits between
the radio and the autopilot's MAVLink link: the autopilot's frames go to it, what it sends the ground goes through
the radio, what the radio delivers goes to it, and what it forwards reaches the autopilot through the run's audit
of the router (a forwarded frame that drives the robot or changes its mode must come from the owner while the lease
last announced is an operator's). The run keeps the native vehicle's lease record, so every §7 figure is computed
by the native rules (``sim.metrics.lease_figures``), with the autopilot's version and mode timeline beside them.
The rover carries the native rover's lidar, whose driver on the vehicle sends the companion OBSTACLE_DISTANCE
(``sim.plants.lidar``), beside the rangefinders the autopilot reports.
"""

from __future__ import annotations

from collections.abc import Hashable
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

from link.proxy import RadioReport
from link.radio import LinkState, subsystem_rng
from link.storage import remove_leftovers
from sim import metrics
from sim.plants.lidar import Lidar
from sim.scenario import Event
from sim.summary import summary
from vehicle.companion import router
from vehicle.companion.app import Companion
from vehicle.companion.ranges import KINDS as RANGE_KINDS
from vehicle.lease import Holder
from vehicle.lease_terms import State
from vehicle.params import Params, load_defaults

# what a forwarded frame needs to be audited: it changes the robot's state under a lease
AUDITED = frozenset((router.Authority.LEASE, router.Authority.MODE))
COMPID_AT = {0xFD: 6, 0xFE: 4}  # MAVLink 2 / 1 start byte -> the byte that holds the sender's component id
AIR_RADIO = "radio"  # the source the vehicle-side radio's frames come from, on the companion's ground side
STATE_NAMES = {v: k.lower().replace("_", " ") for k, v in vars(State).items() if k.isupper()}


def companion_params(scenario_params: dict[str, float], body_radius: float, param_file: Path | None = None) -> Params:
    """The companion's returnlink parameters in a run: the defaults, RTL_BODY_R the robot's footprint (as its
    integrator would set a real one's, and as the native vehicle's is set: ``sim.driver``), then the scenario's own.
    With the footprint the return keeps the body off what the rover's range sensors see (``vehicle.standoff``).

    A served companion boots from ``param_file`` (``sim serve --params``: a torn write's leftovers cleared first;
    StoredFileError if it is damaged) when it exists, the footprint being then the file's, as the native vehicle
    boots from its own (``sim.driver.simulated_vehicle``)."""
    if param_file is not None:
        remove_leftovers(param_file)
    if param_file is not None and param_file.is_file():
        params = load_defaults(param_file)
    else:
        params = load_defaults()
        params.set("RTL_BODY_R", body_radius)
    for k, v in scenario_params.items():
        params.set(k, v)
    return params


class CompanionSide:
    """The companion's half of a plant; mixed in before the autopilot's plant (``AutopilotPlant``), whose
    ``link``, ``heard``, ``_op_name``, ``frame_offset``, ``firmware_modes`` and ``_autopilot_estimate`` it uses.
    ``WORDS`` names the autopilot in the summary; ``FAILURE`` is its run's error."""

    leases = True
    contingency = None  # the companion flies its return plan, never a baseline
    # (the autopilot as the summary's first line names it, where the companion sits, "to X", "X's", the modes)
    WORDS = ("firmware {version}", "telemetry port", "the firmware", "the firmware's", "firmware modes")
    FAILURE: type[Exception] = RuntimeError

    def _init_companion(self, params: Params, autopilot_name: str, options: dict) -> None:
        """The companion on this plant's wire (called by the plant's constructor, the autopilot's link made)."""
        self.to_ground: list[bytes] = []
        self.companion = Companion(params, self._to_autopilot, self.to_ground.append, seed=self.seed, pivots=True,
                                   autopilot_name=autopilot_name, **options)
        self._parser = apm.MAVLink(None, 0, 0)
        self._parser.robust_parsing = True
        self.forwarded = 0  # ground frames the companion passed to the autopilot
        self.stale = 0  # of those, the ones the run's audit of the router found outside the operator's lease
        self._events_read = 0  # the companion's lease transitions the audit has read (``EventQueue.log``)
        self._last_event = None  # ... and the last of them: the lease last announced
        self.air_radio = RadioReport()  # the vehicle-side telemetry radio: its own sequence numbers
        # the native rover's lidar, through its driver on the vehicle (OBSTACLE_DISTANCE, issue 41)
        self.lidar = Lidar(self.world, self.robot, subsystem_rng(self.seed, "lidar"))

    @property
    def vehicle(self):
        """The companion's vehicle (None until it has booted on the autopilot's estimate)."""
        return self.companion.vehicle

    # ----- the scenario around it ------------------------------------------------------------------------------
    def event(self, ev: Event, st, t: float) -> str | None:
        """A lease claim or a parameter change reaches the companion through the operator's station; the rest as
        for the autopilot's own failsafes."""
        if ev.action in ("claim", "param") and (ev.station or self.scenario.operator_station) == self._op_name \
                and self.operator is not None:
            if ev.action == "claim":
                self.operator.gs.claim(-1)
            else:
                self.operator.gs.param_set(ev.name, ev.value)
            return None
        return super().event(ev, st, t)

    # ----- one tick: the vehicle's side of the radio is the companion ------------------------------------------
    def frames(self, t: float) -> list[bytes]:
        """The autopilot's frames to the companion; what the companion sends the ground, through the radio."""
        for data in self.link.drain(t):
            self.companion.from_autopilot(data, t)
        sysid = self.companion.driver.seen.sysid
        if sysid is not None and self.lidar.due(t):
            self.companion.from_autopilot(self.lidar.frame(t, sysid), t)
        out = list(self.to_ground)
        self.to_ground.clear()
        return out

    def receive(self, frames: list[tuple[bytes, str]], t: float) -> None:
        for data, src in frames:
            self.companion.from_ground(data, t, src)
            if src == self._op_name:
                self.heard.append(t)

    def tick(self, t: float) -> None:
        self.companion.tick(t)

    def radio_status(self, state: LinkState, t: float) -> None:
        """The vehicle-side radio's RADIO_STATUS, straight onto the companion's ground port (the radio sits on the
        robot: no radio hop, no loss)."""
        self.companion.from_ground(self.air_radio.frame(state), t, AIR_RADIO)

    def pinned(self) -> list[Hashable]:
        """The owner's ground address, which a real-time transport must keep."""
        return self.companion.pinned()

    def close(self) -> None:
        """The autopilot stopped, then the companion's signing timestamp to disk."""
        try:
            super().close()
        finally:
            self.companion.close()

    def _to_autopilot(self, data: bytes) -> None:
        """The companion's wire to the autopilot; a ground frame it forwards is audited on the way."""
        at = COMPID_AT.get(data[0]) if data else None
        if at is not None and len(data) > at and data[at] != router.COMPANION_COMPID:
            self.forwarded += 1
            self._audit_forwarded(data)
        self.link.send(data)

    def _audit_forwarded(self, data: bytes) -> None:
        """An independent check of the router, as the loop's audit checks the vehicle's guard: a forwarded
        frame that drives the robot or changes its mode must come from the owner while the lease last announced
        (LEASE_EVENT) is an operator's."""
        v = self.vehicle
        if v is None:
            return
        new = v.log(self._events_read)  # (the lease transitions since the last audit: most frames, none)
        if new:
            self._events_read += len(new)
            self._last_event = new[-1]
        if self._last_event is None:
            return
        for m in self._parser.parse_buffer(data) or ():
            if m.get_type() == "BAD_DATA" or router.authority(m) not in AUDITED:
                continue
            if self._last_event.holder is not Holder.OPERATOR or m.get_srcSystem() != v.status().book.owner:
                self.stale += 1

    # ----- the record ------------------------------------------------------------------------------------------
    def estimate(self) -> tuple[float, float]:
        """The companion's estimate in the true frame; the autopilot's own until the companion has booted."""
        v = self.vehicle
        if v is None:
            return self._autopilot_estimate()
        p = v.status().pose
        ox, oy = self.frame_offset
        return ox + p.x, oy + p.y

    def status(self) -> str:
        """The autopilot's mode, and the companion's lease: its state and holder."""
        v = self.vehicle
        if v is None:
            return f"{super().status()}  companion booting"
        s = v.status()
        cur = s.book.current
        holder = "none" if cur is None else cur.holder.name.lower()
        return f"{super().status()}  lease {STATE_NAMES.get(s.state, '?')} ({holder})"

    def range_words(self) -> str:
        """What the companion heard of the rover's range data, for the summary."""
        r = self.companion.driver.ranges
        if r.first_heard is None:
            return "range data: none heard (the return kept no standoff)"
        counts = r.counts
        dropped = {k: n for k, n in sorted(counts.items()) if k not in ("messages", "beams", *RANGE_KINDS)}
        return (f"range data: {counts.get('beams', 0)} beams in {counts.get('messages', 0)} messages "
                f"({r.describe()}), dropped {dropped or 'none'}")

    # ----- the figures -----------------------------------------------------------------------------------------
    def figures(self, run) -> dict:
        """Every figure by the native rules, from the companion's own lease record, and the autopilot's version
        and modes as for every run of it."""
        if self.vehicle is None:
            raise self.FAILURE(f"the companion never started: {self.autopilot} reported no position estimate in "
                               f"{run.t:.1f} simulated s")
        m = metrics.lease_figures(run)
        m["frames"] = {**m["frames"], "estimator_rmse_m": f"true (the companion's estimate, through "
                       f"{self.autopilot}'s EKF origin: the scenario's start)"}
        m["firmware"] = self.link.tap.version
        m["firmware_modes"] = self.firmware_modes
        return m

    def summary(self, run, m: dict) -> str:
        """The native summary, with the autopilot, what the companion passed and refused, and its modes."""
        c = self.companion.counters
        name, where, to, its, modes_title = self.WORDS
        about = [f"  {name.format(version=m['firmware'])} (booted in {self.link.boot_s:.1f} simulated s before "
                 f"scenario time 0), returnlink companion on its {where}",
                 f"  the companion forwarded {c['forwarded']} ground frames to {to}, refused {c['refused']}, "
                 f"relayed {c['relayed']} of {its} to the ground; keepalives {self.companion.driver.keepalives}",
                 f"  {self.range_words()}"]
        return summary(run, m, about, modes_title)
