"""The companion plant: returnlink companion beside the real ArduPilot Rover firmware, in the scenario's world
(``returnlink sim run SCENARIO --vehicle ardurover --policy companion``; docs/architecture.md §10-§11).

The firmware flies in lockstep exactly as for its own failsafes (``sim.plants.firmware.FirmwarePlant``), and the
companion (``vehicle.companion.app.Companion``, the very object ``returnlink companion`` runs) sits between the
radio model and the firmware's MAVLink port, as it would sit between a telemetry radio and the autopilot's TELEM
port: what the firmware says reaches the companion, which relays it and its own frames (LEASE_STATUS, LEASE_EVENT,
...) to the ground through the radio; what the radio delivers from the stations reaches the companion, which passes
to the firmware only what the lease allows. Same seeds, same jams, same RADIO_STATUS as every other plant. It ticks
at 50 Hz on simulated time, after the radio has delivered in each tick; its frames to the firmware go out at once
(the firmware waits for its physics answer meanwhile, so which of its loops sees them never depends on timing),
its frames to the ground leave through the radio with the next tick's.

The telemetry radio has two ends here as on a real rover: the operator's reports to its ground station (as for every
plant), and the vehicle-side radio on the companion's ground port, which injects RADIO_STATUS once a second as a
SiK radio does, its ``rssi`` the operator station's signal at the robot (the radio model's channel, quantised to
SiK units by ``link.proxy.RadioReport``). The companion reads it as it would read a real radio's
(``vehicle.radio_status``): the link map's ``rssi_dbm`` and the crumbs' RSSI. Like the native vehicle, fed the same
channel at the same moments (``sim.runner.Run._radio_status``), the radio reports nothing while the operator's
station is dead or jammed. ``linkmap.csv`` is the companion's map (``sim.outputs``), in the autopilot's local frame
(x north, y east from the scenario's start, ``frame_offset``), as the vehicle knows it.

The companion's returnlink parameters are the native vehicle's: the defaults with the scenario's own on top. The
firmware's are those of ``firmware_params("companion")``: its GCS failsafe on with Hold as the backstop, the rest
of what ``returnlink companion --check`` asks for.

The run keeps the native vehicle's lease record (``sim.lease_record``) beside the firmware's own rows, so every
§7 figure is computed by the native rules (``sim.metrics.lease_figures``), none is null for want of a lease:
return start and end from its LEASE_EVENTs, the reaction from the moment its trigger's condition became true, the
trail it laid, the stale commands (the vehicle's own guard, plus the run's audit of every frame the router
forwarded to the firmware), the scenario's whole verdict. The companion's vehicle works in the autopilot's local
frame, whose origin is the scenario's start (``frame_offset``); the record keeps positions in the true frame, the
estimate the companion's (which fuses the autopilot's EKF) through that origin. Before the companion has booted
(it waits for the autopilot's first position estimate, a fraction of a second into the run) the trace's estimate
is the firmware's own.
"""

from __future__ import annotations

from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

from gcs.plans import from_plan_items
from link.proxy import RadioReport
from link.radio import LinkState
from sim import metrics
from sim.firmware.companion_operator import CompanionOperator
from sim.firmware.lockstep import SPEEDUP
from sim.firmware.process import FirmwareError
from sim.plants.firmware import FirmwarePlant
from sim.policies import COMPANION_POLICY, FIRMWARE_VEHICLE
from sim.scenario import Event, Scenario
from vehicle.companion import router
from vehicle.companion.app import Companion
from vehicle.lease import Holder
from vehicle.params import Params, load_defaults

# what a forwarded frame needs to be audited: it changes the robot's state under a lease
_AUDITED = frozenset((router.Authority.LEASE, router.Authority.MODE))
_COMPID_AT = {0xFD: 6, 0xFE: 4}  # MAVLink 2 / 1 start byte -> the byte that holds the sender's component id
AIR_RADIO = "radio"  # the source the vehicle-side radio's frames come from, on the companion's ground side


class CompanionPlant(FirmwarePlant):
    """The firmware with returnlink companion on its telemetry port (see the module docstring). ``companion`` is
    the companion; ``vehicle`` its vehicle once booted; ``forwarded`` the ground frames it passed to the firmware.

    ``params`` (the defaults with the scenario's own on top, if not given) and ``companion_options`` are the
    companion's, as ``sim serve`` boots it with its kept files and key."""

    policies = (COMPANION_POLICY,)
    leases = True

    def __init__(self, scenario: Scenario, kind: str = FIRMWARE_VEHICLE, seed: int | None = None,
                 policy: str = COMPANION_POLICY, firmware: Path | None = None, log_path: Path | None = None,
                 speedup: float = SPEEDUP, params: Params | None = None, **companion_options) -> None:
        super().__init__(scenario, kind, seed, policy, firmware, log_path, speedup)
        if params is None:
            params = load_defaults()
            for k, v in scenario.params.items():
                params.set(k, v)
        self.to_ground: list[bytes] = []
        self.companion = Companion(params, self._to_autopilot, self.to_ground.append, seed=self.seed, pivots=True,
                                   autopilot_name="the ArduPilot firmware", **companion_options)
        self._parser = apm.MAVLink(None, 0, 0)
        self._parser.robust_parsing = True
        self.forwarded = 0  # ground frames the companion passed to the firmware
        self.stale = 0  # of those, the ones the run's audit of the router found outside the operator's lease
        self.air_radio = RadioReport()  # the vehicle-side telemetry radio: its own sequence numbers

    def _make_operator(self, sc: Scenario) -> CompanionOperator:
        return CompanionOperator(sc.route, sc.resume_route, self.origin, from_plan_items(sc.plan), sc.attempts,
                                 sysid=sc.station(sc.operator_station).sysid)

    @property
    def vehicle(self):
        """The companion's ``Vehicle`` (None until it has booted on the autopilot's estimate)."""
        return self.companion.vehicle

    # ----- the scenario around it ------------------------------------------------------------------------------
    def event(self, ev: Event, st, t: float) -> str | None:
        """A lease claim or a parameter change reaches the companion through the operator's station; the rest as
        for the firmware's own failsafes."""
        if ev.action in ("claim", "param") and (ev.station or self.scenario.operator_station) == self._op_name:
            if ev.action == "claim":
                self.operator.gs.claim(-1)
            else:
                self.operator.gs.param_set(ev.name, ev.value)
            return None
        return super().event(ev, st, t)

    # ----- one tick: the vehicle's side of the radio is the companion ------------------------------------------
    def frames(self, t: float) -> list[bytes]:
        """The firmware's frames to the companion; what the companion sends the ground, through the radio."""
        for data in self.link.drain(t):
            self.companion.from_autopilot(data, t)
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

    def _to_autopilot(self, data: bytes) -> None:
        """The companion's wire to the firmware; a ground frame it forwards is audited on the way."""
        at = _COMPID_AT.get(data[0]) if data else None
        if at is not None and len(data) > at and data[at] != router.COMPANION_COMPID:
            self.forwarded += 1
            self._audit_forwarded(data)
        self.link.send(data)

    def _audit_forwarded(self, data: bytes) -> None:
        """An independent check of the router, as the loop's audit checks the vehicle's guard: a forwarded
        frame that drives the robot or changes its mode must come from the owner while the lease last announced
        (LEASE_EVENT) is an operator's."""
        v = self.vehicle
        if v is None or not v.event_log:
            return
        for m in self._parser.parse_buffer(data) or ():
            if m.get_type() == "BAD_DATA" or router.authority(m) not in _AUDITED:
                continue
            if v.event_log[-1].holder is not Holder.OPERATOR or m.get_srcSystem() != v.book.owner:
                self.stale += 1

    # ----- the record ------------------------------------------------------------------------------------------
    def estimate(self) -> tuple[float, float]:
        """The companion's estimate in the true frame; the firmware's own until the companion has booted."""
        v = self.vehicle
        if v is None:
            return self._autopilot_estimate()
        p = v.estimator.pose
        ox, oy = self.frame_offset
        return ox + p.x, oy + p.y

    # ----- the figures -----------------------------------------------------------------------------------------
    def figures(self, run) -> dict:
        """Every figure by the native rules, from the companion's own lease record, and the firmware's version and
        modes as for every firmware run."""
        if self.vehicle is None:
            raise FirmwareError(f"the companion never started: the firmware reported no position estimate in "
                                f"{run.t:.1f} simulated s")
        m = metrics.lease_figures(run)
        m["frames"] = {**m["frames"], "estimator_rmse_m": "true (the companion's estimate, through the firmware's "
                       "EKF origin: the scenario's start)"}
        m["firmware"] = self.link.tap.version
        m["firmware_modes"] = self.firmware_modes
        return m

    def summary(self, run, m: dict) -> str:
        """The native summary, with the firmware, what the companion passed and refused, and the firmware's modes."""
        lines = metrics.summary(run, m).splitlines()
        c = self.companion.counters
        extra = [f"  firmware {m['firmware']} (booted in {self.link.boot_s:.1f} simulated s before scenario time "
                 f"0), returnlink companion on its telemetry port",
                 f"  the companion forwarded {c['forwarded']} ground frames to the firmware, refused "
                 f"{c['refused']}, relayed {c['relayed']} of the firmware's to the ground; keepalives "
                 f"{self.companion.driver.keepalives}"]
        modes = ["  firmware modes:"] + [f"    {e['t']:7.2f} s  {e['mode']}" for e in m["firmware_modes"]]
        notes = [f"  note: {n}" for n in run.notes]
        return "\n".join([lines[0], *extra, *lines[1:-1], *modes, *notes, lines[-1]])

