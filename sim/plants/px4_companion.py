"""The PX4 companion plant: returnlink companion beside the real PX4 rover, in the scenario's world
(``returnlink sim run SCENARIO --vehicle px4rover --policy companion``; docs/architecture.md §10.1, §11.2).

PX4 flies in lockstep exactly as for its own failsafes (``sim.plants.px4.PX4Plant``), and the companion
(``vehicle.companion.app.Companion``, the very object ``returnlink companion`` runs; it recognises PX4 from its
HEARTBEAT) sits between the radio model and PX4's GCS link, as it would sit between a telemetry radio and the
autopilot's TELEM port: what PX4 says reaches the companion, which relays it and its own frames to the ground through
the radio; what the radio delivers from the stations reaches the companion, which passes to PX4 only what the lease
allows (the operator's heartbeats never: PX4's data link is the companion's keepalive). It ticks at 50 Hz on
simulated time after the radio has delivered, as the ArduPilot companion plant's does (``sim.plants.companion``),
whose vehicle-side radio (RADIO_STATUS once a second onto the companion's ground port), audit of forwarded frames,
lease record and figures this plant shares.

PX4's parameters: the SITL's and airframe 1069's, with what ``returnlink companion --configure`` would set
(``vehicle.companion.setup.PX4_NEEDS`` applied to PX4's own defaults: NAV_DLL_ACT 1 and COM_DL_LOSS_T 5, the
backstop for a dead companion; COM_OF_LOSS_T 0.5 and COM_OBL_RC_ACT 5, Hold for one that dies mid-return and the
owner's dead-man), and the run's own needs as for PX4's failsafes (``px4_params``): COM_DISARM_PRFLT -1 (no
pre-flight disarm while the operator gets going) and RO_SPEED_LIM the scenario's fastest route speed (PX4's Offboard
position target has no speed of its own; the companion's velocity targets carry the return's, which drives the trail
at the speed it was driven out). COM_OF_LOSS_T is short here, not the 60 s of the failsafe baselines: beside the
companion the Offboard loss is part of the backstop, and the companion's return, not PX4's data-link failsafe, is
measured.
"""

from __future__ import annotations

from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

from gcs.plans import from_plan_items
from link.proxy import RadioReport
from link.radio import LinkState
from sim import metrics
from sim.plants.companion import AIR_RADIO
from sim.plants.px4 import PX4Plant
from sim.policies import COMPANION_POLICY, PX4_VEHICLE
from sim.px4.companion_operator import PX4CompanionOperator
from sim.px4.process import PX4Error
from sim.scenario import Event, Scenario, Station
from vehicle.companion import router
from vehicle.companion.app import Companion
from vehicle.companion.setup import PX4_NEEDS
from vehicle.lease import Holder
from vehicle.params import Params, load_defaults

# what a forwarded frame needs to be audited (it changes the robot's state under a lease), and where a MAVLink 2 / 1
# frame holds its sender's component id: as the ArduPilot companion plant's audit reads them
_AUDITED = frozenset((router.Authority.LEASE, router.Authority.MODE))
_COMPID_AT = {0xFD: 6, 0xFE: 4}

# PX4's own defaults of what the companion checks (src/modules/commander/commander_params.c), which --configure
# starts from
PX4_DEFAULTS: dict[str, float] = {"NAV_DLL_ACT": 0, "COM_DL_LOSS_T": 10, "COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 0}


def configured(values: dict[str, float]) -> dict[str, float]:
    """``values`` after ``returnlink companion --configure``: each PX4 need that differs set to its fix."""
    out = dict(values)
    for need in PX4_NEEDS:
        v = out.get(need.name)
        if v is not None and not need.ok(v):
            out[need.name] = need.fix(v)
    return out


def px4_companion_params(speed_limit: float) -> dict[str, float]:
    """PX4's parameters in a companion run (see the module docstring)."""
    return {**configured(PX4_DEFAULTS), "COM_DISARM_PRFLT": -1, "RO_SPEED_LIM": round(speed_limit, 3)}


class PX4CompanionPlant(PX4Plant):
    """PX4 with returnlink companion on its telemetry link (see the module docstring). ``companion`` is the
    companion; ``vehicle`` its vehicle once booted; ``forwarded`` the ground frames it passed to PX4."""

    policies = (COMPANION_POLICY,)
    leases = True

    def __init__(self, scenario: Scenario, kind: str = PX4_VEHICLE, seed: int | None = None,
                 policy: str = COMPANION_POLICY, px4: Path | None = None, log_path: Path | None = None,
                 accept_timeout_s: float | None = None, params: Params | None = None, **companion_options) -> None:
        super().__init__(scenario, kind, seed, policy, px4, log_path, accept_timeout_s)
        self.lnk_timeout = float(scenario.params.get("LNK_TIMEOUT", 3.0))  # the companion's, not PX4's
        if params is None:
            params = load_defaults()
            for k, v in scenario.params.items():
                params.set(k, v)
        self.to_ground: list[bytes] = []
        self.companion = Companion(params, self._to_autopilot, self.to_ground.append, seed=self.seed, pivots=True,
                                   autopilot_name="PX4", **companion_options)
        self._parser = apm.MAVLink(None, 0, 0)
        self._parser.robust_parsing = True
        self.forwarded = 0  # ground frames the companion passed to PX4
        self.stale = 0  # of those, the ones the run's audit of the router found outside the operator's lease
        self.air_radio = RadioReport()  # the vehicle-side telemetry radio: its own sequence numbers

    @staticmethod
    def _px4_params(policy: str, lnk_timeout: float, speed_limit: float) -> dict[str, float]:
        return px4_companion_params(speed_limit)

    @property
    def vehicle(self):
        """The companion's ``Vehicle`` (None until it has booted on PX4's estimate)."""
        return self.companion.vehicle

    # ----- the scenario around it ------------------------------------------------------------------------------
    def station(self, spec: Station, operator: bool) -> tuple[PX4CompanionOperator | None, None]:
        if not operator:
            return None, None
        sc = self.scenario
        self.operator = PX4CompanionOperator(sc.route, sc.resume_route, self.geo, from_plan_items(sc.plan),
                                             sc.attempts, sysid=spec.sysid)
        return self.operator, None

    def event(self, ev: Event, st, t: float) -> str | None:
        """A lease claim or a parameter change reaches the companion through the operator's station; a scripted
        RTL goes to the companion too (``request_rtl``); the rest as for PX4's own failsafes."""
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
        """PX4's frames to the companion; what the companion sends the ground, through the radio."""
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
        """The vehicle-side radio's RADIO_STATUS, straight onto the companion's ground port."""
        self.companion.from_ground(self.air_radio.frame(state), t, AIR_RADIO)

    def _to_autopilot(self, data: bytes) -> None:
        """The companion's wire to PX4; a ground frame it forwards is audited on the way."""
        at = _COMPID_AT.get(data[0]) if data else None
        if at is not None and len(data) > at and data[at] != router.COMPANION_COMPID:
            self.forwarded += 1
            self._audit_forwarded(data)
        self.link.send(data)

    def _audit_forwarded(self, data: bytes) -> None:
        """A forwarded frame that drives the robot or changes its mode must come from the owner while the lease
        last announced is an operator's (``sim.plants.companion.CompanionPlant._audit_forwarded``)."""
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
        """The companion's estimate in the true frame; PX4's own until the companion has booted."""
        v = self.vehicle
        if v is None:
            return super().estimate()
        p = v.estimator.pose
        ox, oy = self.frame_offset
        return ox + p.x, oy + p.y

    # ----- the figures -----------------------------------------------------------------------------------------
    def figures(self, run) -> dict:
        """Every figure by the native rules, from the companion's own lease record, and PX4's version and nav
        states as for every PX4 run."""
        if self.vehicle is None:
            raise PX4Error(f"the companion never started: PX4 reported no position estimate in {run.t:.1f} "
                           f"simulated s")
        m = metrics.lease_figures(run)
        m["frames"] = {**m["frames"], "estimator_rmse_m": "true (the companion's estimate, through PX4's EKF2 "
                       "origin: the scenario's start)"}
        m["firmware"] = self.link.tap.version
        m["firmware_modes"] = self.firmware_modes
        return m

    def summary(self, run, m: dict) -> str:
        """The native summary, with PX4, what the companion passed and refused, and PX4's nav states."""
        lines = metrics.summary(run, m).splitlines()
        c = self.companion.counters
        extra = [f"  {m['firmware']} (booted in {self.link.boot_s:.1f} simulated s before scenario time 0), "
                 f"returnlink companion on its telemetry link",
                 f"  the companion forwarded {c['forwarded']} ground frames to PX4, refused {c['refused']}, relayed "
                 f"{c['relayed']} of PX4's to the ground; keepalives {self.companion.driver.keepalives}"]
        modes = ["  PX4 nav states:"] + [f"    {e['t']:7.2f} s  {e['mode']}" for e in m["firmware_modes"]]
        notes = [f"  note: {n}" for n in run.notes]
        return "\n".join([lines[0], *extra, *lines[1:-1], *modes, *notes, lines[-1]])
