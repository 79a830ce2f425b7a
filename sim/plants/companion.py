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

from gcs.plans import from_plan_items
from sim import registry
from sim.firmware.companion_operator import CompanionOperator
from sim.firmware.lockstep import SPEEDUP
from sim.firmware.process import FirmwareError
from sim.plants.beside import CompanionSide, companion_params
from sim.plants.firmware import FirmwarePlant
from sim.scenario import Scenario
from vehicle.params import Params


class CompanionPlant(CompanionSide, FirmwarePlant):
    """The firmware with returnlink companion on its telemetry port (see the module docstring). ``companion`` is
    the companion; ``vehicle`` its vehicle once booted; ``forwarded`` the ground frames it passed to the firmware.

    ``params`` (the defaults with the scenario's own on top, if not given) and ``companion_options`` are the
    companion's, as ``sim serve`` boots it with its kept files and key."""

    policies = registry.COMPANION_PLANT.policies
    FAILURE = FirmwareError
    rangefinders = True  # the rover's six, which the firmware reports as DISTANCE_SENSOR (issue 41)

    def __init__(self, scenario: Scenario, kind: str = FirmwarePlant.kind, seed: int | None = None,
                 policy: str = policies[0], firmware: Path | None = None, log_path: Path | None = None,
                 speedup: float = SPEEDUP, params: Params | None = None, **companion_options) -> None:
        super().__init__(scenario, kind, seed, policy, firmware, log_path, speedup)
        if params is None:
            params = companion_params(scenario.params, self.robot.shape.radius, companion_options.get("param_file"))
        self._init_companion(params, "the ArduPilot firmware", companion_options)

    def _make_operator(self, sc: Scenario) -> CompanionOperator:
        return CompanionOperator(sc.route, sc.resume_route, self.origin, from_plan_items(sc.plan), sc.attempts,
                                 sysid=sc.station(sc.operator_station).sysid, rejoin=sc.rejoin)
