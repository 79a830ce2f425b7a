"""The one place a room outside the core boots it and names what it needs of it (docs/architecture.md §2 "Ports").

The companion (``vehicle.companion``) and the simulator's plants (``sim.driver``) build the native vehicle here
rather than importing ``vehicle.app``, so the one thing they can name of the core is its port and its tick: this is
the composition root for those rooms, and all it hands back is a ``Core``. The tick's period (``DT``), the
RETURNLINK_STATE values (``State``) and the real-time shell (``run``) come from here too, so nothing in ``sim/``,
``gcs/``, ``link/`` or ``benchmarks/`` imports ``vehicle.app`` or ``vehicle.control`` (``tests/test_layout.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from vehicle.app import Vehicle, run
from vehicle.contingency import Contingency
from vehicle.io import RobotDriver
from vehicle.lease_terms import State
from vehicle.params import Params
from vehicle.port import DT, VehiclePort

__all__ = ["DT", "Core", "State", "boot_core", "run"]


class Core(VehiclePort, Protocol):
    """The core as whoever booted it sees it: its port, and the tick that whoever drives its clock calls (a plant,
    the companion, ``run``)."""

    def tick(self, t: float) -> tuple[float, float]:
        """One 50 Hz tick at time ``t``: the speed and yaw rate commanded."""


def boot_core(driver: RobotDriver, params: Params, pose: tuple[float, float, float], t: float, *, seed: int = 0,
              boot_epoch: int | None = None, on_epoch: Callable[[int], str | None] | None = None,
              contingency: Contingency | None = None) -> Core:
    """A native vehicle on ``driver`` at ``pose`` and time ``t`` (``vehicle.app.Vehicle``: ``boot_epoch`` None
    derives the first epoch from ``seed``, as only the lockstep simulator may), told of each epoch it issues
    through ``on_epoch`` before anyone hears of it; ``contingency`` a link-loss behaviour to fly instead of the
    return plan (the simulator's baselines)."""
    return Vehicle(driver, params, pose, t, seed=seed, boot_epoch=boot_epoch, contingency=contingency,
                   on_epoch=on_epoch)
