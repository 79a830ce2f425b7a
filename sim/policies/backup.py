"""``backup``: back up along the path driven until the link is good again, the baseline of the literature.

The usual comparison in the research on communication-aware teleoperation (a robot that "backtracks until it
reconnects"): on link loss the robot retraces the path it drove, newest part first, with no target and no
displacement bound, and stops the moment the link is good again. Here the path is the vehicle's own breadcrumb
trail (estimate frame) reversed point by point, loops included, from the current position back to the trail's
start; the robot stands still while the vehicle's link tag says the owner is heard well (``link_is_good``) and
backs up again if it goes bad before the lease book declares LINK_REGAINED, which ends the block as for any
return. It completes at the trail's start. An operator's RTL over a good link has no link to wait for: it backs
up the whole trail, as any operator-commanded return runs to its target (docs/architecture.md §6).
"""

from __future__ import annotations

import numpy as np

from sim.policies.base import Baseline, Command, PathDriver, return_speed
from vehicle.port import Snapshot


class Backup(Baseline):
    def __init__(self) -> None:
        super().__init__()
        self.driver: PathDriver | None = None
        self.after_loss = True  # False: an operator's RTL over a good link, which backs up the whole trail

    def begin(self, vehicle: Snapshot, t: float, x: float, y: float) -> None:
        super().begin(vehicle, t, x, y)
        trail = vehicle.trail_points()
        self.route = np.vstack([[[x, y]], trail[::-1]]) if len(trail) else np.array([[x, y]])
        self.target = (float(self.route[-1, 0]), float(self.route[-1, 1]))
        self.driver = PathDriver(self.route, return_speed(vehicle), t)
        self.after_loss = vehicle.status().book.link.lost

    def tick(self, vehicle: Snapshot, t: float, x: float, y: float, yaw: float) -> Command:
        assert self.driver is not None
        if self.after_loss and vehicle.status().link_good:
            self.driver.last_progress_at = t  # standing still on purpose is not being stuck
            return 0.0, 0.0, None
        return self.driver.step(vehicle, t, x, y, yaw)
