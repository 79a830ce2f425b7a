"""``returnlink sim serve SCENARIO --vehicle ardurover --policy companion``: returnlink companion beside the real
ArduPilot firmware in a scenario's world, in real time (or K times faster), for a ground station of your own.

The firmware paces itself and answers its physics as under ``sim serve --vehicle ardurover``
(``sim.firmware.serve.FirmwareServer``); the companion (``vehicle.companion.app.Companion``, the object
``returnlink companion`` runs on a robot) sits between the radio proxy and the firmware's MAVLink port, where it
sits between a telemetry radio and an autopilot's TELEM port. So QGroundControl, MAVProxy or MAVSDK on
127.0.0.1:14550/14540 see the firmware's own stream and the companion's (component 191: LEASE_STATUS, LEASE_EVENT),
take control through the companion (MAV_CMD_REQUEST_OPERATOR_CONTROL), upload a return plan to it, fly the
firmware in GUIDED and feel the link die where the scenario says: the companion's return starts after LNK_TIMEOUT
and halts where the link comes back, as in ``sim run --policy companion``. No scripted operator: you are the
operator.

The companion keeps what ``sim serve`` keeps for the native vehicle: boot parameters from ``--params FILE`` (the
scenario's on top of the defaults otherwise), the epochs it issued (``--state``), and with ``--key`` it signs with
that key and obeys only frames signed with it, its signing clock the wall clock, as ground stations' are.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from link.signing import stamp_from_unix
from link.storage import remove_leftovers
from sim.firmware.serve import FirmwareServer
from sim.plants.companion import CompanionPlant
from sim.policies import COMPANION_POLICY
from sim.scenario import Scenario
from vehicle.epochs import EpochLog
from vehicle.keystore import KeyStore
from vehicle.lease_terms import State
from vehicle.params import load_defaults

_STATE_NAMES = {v: k.lower().replace("_", " ") for k, v in vars(State).items() if k.isupper()}


def companion_boot(scenario: Scenario, epochs: EpochLog, param_file: Path | None,
                   keystore: KeyStore | None) -> dict:
    """What a served companion boots with, as ``sim serve`` boots the native vehicle
    (``sim.driver.simulated_vehicle``): the parameter file (a torn write's leftovers cleared first), else the
    defaults, the scenario's own on top; the epochs it issued; with a key, the wall clock as its signing clock."""
    if param_file is not None:
        remove_leftovers(param_file)
    params = load_defaults(param_file) if param_file is not None and param_file.is_file() else load_defaults()
    for k, v in scenario.params.items():
        params.set(k, v)
    return {"params": params, "keystore": keystore, "stamp": lambda t: stamp_from_unix(time.time()),
            "boot_epoch": epochs.boot, "param_file": param_file, "on_epoch": epochs.issued}


class CompanionServer(FirmwareServer):
    """The firmware served with returnlink companion on its telemetry port (see the module docstring): the companion
    plant (``sim.plants.companion``), its companion booted as ``sim serve`` boots the native vehicle."""

    plant_type = CompanionPlant

    def __init__(self, scenario: Scenario, seed: int | None, firmware: Path, port: int = 14580,
                 peers: tuple[tuple[str, int], ...] = (("127.0.0.1", 14550), ("127.0.0.1", 14540)),
                 perfect_link: bool = False, speedup: float = 1.0, duration: float = math.inf,
                 log_path: Path | None = None, out=sys.stderr, param_file: Path | None = None,
                 keystore: KeyStore | None = None, epochs_file: Path | None = None) -> None:
        self.epochs = EpochLog(epochs_file)
        super().__init__(scenario, seed, COMPANION_POLICY, firmware, port, peers, perfect_link, speedup, duration,
                         log_path, out, **companion_boot(scenario, self.epochs, param_file, keystore))
        self.companion = self.plant.companion
        self.to_ground = self.plant.to_ground
        self.transport.pinned = self.companion.pinned  # the owner's address is never crowded out

    def _tick(self, t: float) -> None:
        proxy = self.proxy
        proxy.update(t)
        companion = self.companion
        for data in self.link.drain(t):
            companion.from_autopilot(data, t)
        for data, addr in proxy.from_ground(t):
            companion.from_ground(data, t, addr)
        companion.tick(t)
        for data in self.to_ground:
            proxy.to_ground(data, t)
        self.to_ground.clear()
        proxy.flush(t)
        self._record_tick(t)

    def _status(self) -> str:
        v = self.companion.vehicle
        if v is None:
            return "  companion booting"
        s = v.status()
        cur = s.book.current
        holder = "none" if cur is None else cur.holder.name.lower()
        return f"  lease {_STATE_NAMES.get(s.state, '?')} ({holder})"

    def run(self) -> CompanionServer:
        try:
            return super().run()
        finally:
            self.companion.close()
