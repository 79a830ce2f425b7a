"""Where a vehicle core is built for a room that must not know its class (docs/architecture.md §2 "Ports").

The companion (``vehicle.companion``) boots the native vehicle on its autopilot's first estimate and then talks to it
only through its port, as every MAVLink service does. It asks here rather than importing ``vehicle.app``, so the
one thing it can name of the core is the port: this is the composition root for that room, and all it hands back is
a ``VehiclePort``.
"""

from __future__ import annotations

from collections.abc import Callable

from vehicle.app import Vehicle
from vehicle.io import RobotDriver
from vehicle.params import Params
from vehicle.port import VehiclePort


def boot_core(driver: RobotDriver, params: Params, pose: tuple[float, float, float], t: float, *, seed: int = 0,
              boot_epoch: int | None = None, on_epoch: Callable[[int], str | None] | None = None) -> VehiclePort:
    """A native vehicle on ``driver`` at ``pose`` and time ``t`` (``vehicle.app.Vehicle``: ``boot_epoch`` None
    derives the first epoch from ``seed``, as only the lockstep simulator may), told of each epoch it issues
    through ``on_epoch`` before anyone hears of it."""
    v = Vehicle(driver, params, pose, t, seed=seed, boot_epoch=boot_epoch)
    v.on_epoch = on_epoch
    return v
