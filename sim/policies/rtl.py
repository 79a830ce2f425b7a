"""``rtl``: return to launch in a straight line, as ArduPilot Rover RTL and PX4 Return do it on a rover.

ArduPilot Rover's RTL mode "drives the vehicle directly back to its home location" (at WP_SPEED or RTL_SPEED) and
stops there; PX4's rover Return likewise heads straight for home. Neither stops when the link comes back: the
vehicle stays in RTL until it arrives or the operator changes the mode. Here the return starts with COMMS_LOST
(the vehicle's own LNK_TIMEOUT, so only the path differs from returnlink), drives a straight line from the
estimated position to home (where the estimator started) at the return speed returnlink would use, completes on
arrival, and keeps going through LINK_REGAINED. A wall in the way stops it with the same STUCK rule every
return has, instead of pushing forever.
"""

from __future__ import annotations

import numpy as np

from sim.policies.base import Baseline, Command, PathDriver, return_speed
from vehicle.port import Snapshot


class StraightRTL(Baseline):
    halts_on_regain = False

    def __init__(self) -> None:
        super().__init__()
        self.driver: PathDriver | None = None

    def begin(self, vehicle: Snapshot, t: float, x: float, y: float) -> None:
        super().begin(vehicle, t, x, y)
        home = vehicle.status().home
        self.target = (float(home[0]), float(home[1]))
        self.route = np.array([[x, y], self.target])
        self.driver = PathDriver(self.route, return_speed(vehicle), t)

    def tick(self, vehicle: Snapshot, t: float, x: float, y: float, yaw: float) -> Command:
        assert self.driver is not None
        return self.driver.step(vehicle, t, x, y, yaw)
