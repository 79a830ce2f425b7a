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

from sim.firmware.companion_serve import CompanionServer, companion_boot
from sim.firmware.serve import FirmwareServer
from sim.plants.px4 import PX4Plant
from sim.plants.px4_companion import PX4CompanionPlant
from sim.policies import COMPANION_POLICY, PX4_VEHICLE
from sim.scenario import Scenario
from vehicle.epochs import EpochLog
from vehicle.keystore import KeyStore


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


class PX4CompanionServer(PX4Server):
    """PX4 served with returnlink companion on its telemetry link (``sim serve --vehicle px4rover --policy
    companion``): the PX4 companion plant (``sim.plants.px4_companion``), its companion booted as the ArduPilot
    one is (``sim.firmware.companion_serve.companion_boot``: ``--params``, ``--state``, ``--key``), and the same
    tick: PX4's frames to the companion, the ground's to the companion, the companion's to the ground."""

    plant_type: type = PX4CompanionPlant
    # the companion's tick, status line and shutdown are the ArduPilot companion server's, whatever autopilot
    _tick = CompanionServer._tick
    _status = CompanionServer._status

    def __init__(self, scenario: Scenario, seed: int | None, px4: Path, port: int = 14580,
                 peers: tuple[tuple[str, int], ...] = (("127.0.0.1", 14550), ("127.0.0.1", 14540)),
                 perfect_link: bool = False, speedup: float = 1.0, duration: float = math.inf,
                 log_path: Path | None = None, out=sys.stderr, param_file: Path | None = None,
                 keystore: KeyStore | None = None, epochs_file: Path | None = None) -> None:
        self.epochs = EpochLog(epochs_file)
        super().__init__(scenario, seed, COMPANION_POLICY, px4, port, peers, perfect_link, speedup, duration,
                         log_path, out, **companion_boot(scenario, self.epochs, param_file, keystore))
        self.companion = self.plant.companion
        self.to_ground = self.plant.to_ground
        self.transport.pinned = self.companion.pinned  # the owner's address is never crowded out

    def run(self) -> PX4CompanionServer:
        try:
            return super().run()
        finally:
            self.companion.close()
