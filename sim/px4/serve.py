"""``returnlink sim serve SCENARIO --vehicle px4rover``: the real PX4 rover in a scenario's world, in real time (or
K times faster), for a ground station of your own (docs/architecture.md §10.1, issue 31).

The PX4 plant (``sim.plants.px4``) behind the radio proxy the other servers use: PX4's GCS link reaches
127.0.0.1:14550 and :14540 (and whoever talks to the UDP port) only through the radio model, so QGroundControl,
MAVProxy or MAVSDK fly PX4 in the scenario's world and its data-link failsafe (``--policy px4-hold|px4-return``)
hears exactly what the radio delivers. No scripted operator: you are the operator (PX4 arms only once it has heard a
ground station's heartbeat). On exit it writes the trajectory plot.

PX4's clock follows the simulator's sensor stream (lockstep), so unlike the ArduPilot firmware, which paces itself,
the server paces the physics to the wall clock: after each 20 ms tick it waits until the wall has caught up with
``t / speedup``. A machine too slow for the pace runs behind it, never ahead.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from sim.firmware.serve import FirmwareServer
from sim.plants.px4 import PX4Plant
from sim.policies import PX4_VEHICLE
from sim.scenario import Scenario


class PX4Server(FirmwareServer):
    """PX4 behind the radio proxy, paced to the wall clock (see the module docstring)."""

    plant_type: type = PX4Plant

    def __init__(self, scenario: Scenario, seed: int | None, policy: str, px4: Path, port: int = 14580,
                 peers: tuple[tuple[str, int], ...] = (("127.0.0.1", 14550), ("127.0.0.1", 14540)),
                 perfect_link: bool = False, speedup: float = 1.0, duration: float = math.inf,
                 log_path: Path | None = None, out=sys.stderr, **plant_options) -> None:
        if not (math.isfinite(speedup) and speedup > 0):
            raise ValueError(f"speedup must be a positive number, got {speedup!r}")
        self._wall0: float | None = None
        super().__init__(scenario, seed, policy, px4, port, peers, perfect_link, speedup, duration, log_path, out,
                         **plant_options)

    def _make_plant(self, px4: Path, log_path: Path | None, **plant_options):
        return self.plant_type(self.scenario, PX4_VEHICLE, self.seed, self.policy, px4, log_path, **plant_options)

    def _boot(self) -> None:
        print("returnlink: PX4 is booting (EKF2 needs its sensors and a GPS fix first)...", file=self.out, flush=True)
        self.plant.start()
        print(f"returnlink: {self.link.tap.version or 'PX4'} ready after {self.link.boot_s:.1f} simulated s; it "
              "arms once it has heard a ground station", file=self.out, flush=True)

    def _paced(self, t: float) -> bool:
        """The tick, then a wait until the wall clock has caught up with ``t / speedup``."""
        self._tick(t)
        now = time.perf_counter()
        if self._wall0 is None:
            self._wall0 = now - t / self.speedup
        ahead = self._wall0 + t / self.speedup - now
        if ahead > 0:
            time.sleep(ahead)
        return True
