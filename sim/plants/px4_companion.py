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

from gcs.plans import from_plan_items
from sim import registry
from sim.plants.beside import CompanionSide, companion_params
from sim.plants.px4 import PX4Plant
from sim.px4.companion_operator import PX4CompanionOperator
from sim.px4.process import PX4Error
from sim.scenario import Scenario, Station
from vehicle.companion.setup import PX4_NEEDS
from vehicle.params import Params

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


class PX4CompanionPlant(CompanionSide, PX4Plant):
    """PX4 with returnlink companion on its telemetry link (see the module docstring). ``companion`` is the
    companion; ``vehicle`` its vehicle once booted; ``forwarded`` the ground frames it passed to PX4."""

    policies = registry.PX4_COMPANION_PLANT.policies
    FAILURE = PX4Error
    rangefinders = True  # the rover's six, through PX4 (DISTANCE_SENSOR on its simulator link): issue 41
    WORDS = ("{version}", "telemetry link", "PX4", "PX4's", "PX4 nav states")

    def __init__(self, scenario: Scenario, kind: str = PX4Plant.kind, seed: int | None = None,
                 policy: str = policies[0], px4: Path | None = None, log_path: Path | None = None,
                 accept_timeout_s: float | None = None, params: Params | None = None, **companion_options) -> None:
        super().__init__(scenario, kind, seed, policy, px4, log_path, accept_timeout_s)
        self.lnk_timeout = float(scenario.params.get("LNK_TIMEOUT", 3.0))  # the companion's, not PX4's
        if params is None:
            params = companion_params(scenario.params, self.robot.shape.radius, companion_options.get("param_file"))
        self._init_companion(params, "PX4", companion_options)

    @staticmethod
    def _px4_params(policy: str, lnk_timeout: float, speed_limit: float) -> dict[str, float]:
        return px4_companion_params(speed_limit)

    def station(self, spec: Station, operator: bool) -> tuple[PX4CompanionOperator | None, None]:
        if not operator:
            return None, None
        sc = self.scenario
        self.operator = PX4CompanionOperator(sc.route, sc.resume_route, self.geo, from_plan_items(sc.plan),
                                             sc.attempts, sysid=spec.sysid, rejoin=sc.rejoin)
        return self.operator, None
