"""The firmware's runs under the names and signatures their callers know (``benchmarks/firmware_bench.py``, the
firmware tests): ``FirmwareRun`` (its own failsafes) and ``CompanionRun`` (returnlink companion beside it). They sit
beside the loop they fix a plant of, not in ``sim/firmware/``, which the plants build on and so never imports them.

Each is the one simulator loop (``sim.runner.Run``) with its plant fixed (``sim.plants.firmware``,
``sim.plants.companion``); the loop's hooks (``_boot``, ``_loop``, ``_tick``) are there to override as for any
run. ``link``, ``rows``, ``heard`` and ``operator`` read the plant's, for the code that measures or drives the
firmware itself.
"""

from __future__ import annotations

from pathlib import Path

from sim.plants.companion import CompanionPlant
from sim.plants.firmware import FirmwarePlant
from sim.registry import default_policy
from sim.runner import Run
from sim.scenario import Scenario


class FirmwareRun(Run):
    """One scenario flown by the firmware's own failsafes; the firmware is stopped when the run ends, raises, or is
    interrupted."""

    plant_type: type = FirmwarePlant

    def __init__(self, scenario: Scenario, seed: int | None = None, policy: str = default_policy(FirmwarePlant.kind),
                 firmware: Path | None = None, progress: bool = False, duration: float | None = None,
                 log_path: Path | None = None) -> None:
        super().__init__(scenario, self.plant_type.kind, seed, progress, duration, policy, plant=self.plant_type,
                         firmware=firmware, log_path=log_path)

    @property
    def link(self):
        """The firmware in lockstep (``sim.firmware.lockstep.Lockstep``)."""
        return self.plant.link

    @property
    def rows(self) -> list[tuple]:
        return self.plant.rows

    @property
    def heard(self) -> list[float]:
        return self.plant.heard

    @property
    def operator(self):
        return self.plant.operator


class CompanionRun(FirmwareRun):
    """One scenario flown by the firmware with returnlink companion on its telemetry port."""

    plant_type = CompanionPlant

    def __init__(self, scenario: Scenario, seed: int | None = None, policy: str = CompanionPlant.policies[0],
                 firmware: Path | None = None, progress: bool = False, duration: float | None = None,
                 log_path: Path | None = None) -> None:
        super().__init__(scenario, seed, policy, firmware, progress, duration, log_path)

    @property
    def companion(self):
        return self.plant.companion

    @property
    def forwarded(self) -> int:
        return self.plant.forwarded
