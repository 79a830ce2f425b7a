"""``hold``: ArduPilot Rover's default GCS failsafe, FS_ACTION=2 (Hold): on link loss, stop and wait.

ArduPilot Rover documents FS_ACTION 2 as "Hold": when the GCS failsafe triggers (no heartbeat for FS_GCS_TIMEOUT,
held for FS_TIMEOUT) the rover switches to HOLD mode, stops, and stays there until the operator changes the mode.
Here the robot stops when the return-service lease becomes current (COMMS_LOST) and never moves on its own; the
teleop dead-man has already stopped it by then, so the extra FS_TIMEOUT of ArduPilot changes nothing. When the
link comes back, the lease book's LINK_REGAINED ends the block and the operator resumes by claiming the fresh
lease, which is the operator changing the mode.
"""

from __future__ import annotations

from sim.policies.base import Baseline, Command
from vehicle.port import Snapshot


class Hold(Baseline):
    holding = True  # HOLD mode, the whole block

    def tick(self, vehicle: Snapshot, t: float, x: float, y: float, yaw: float) -> Command:
        return 0.0, 0.0, None
