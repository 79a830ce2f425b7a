"""The package boundaries of the layout: the onboard software runs without the simulator, and a ground station
needs only the protocol in ``link/``, never the onboard package."""

from __future__ import annotations

import subprocess
import sys


def _loaded_after_importing(modules: list[str]) -> set[str]:
    code = ("import importlib, sys\n"
            f"for m in {modules!r}: importlib.import_module(m)\n"
            "print('\\n'.join(sorted({n.split('.')[0] for n in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    return set(out.stdout.split())


def test_the_ground_station_needs_no_onboard_code():
    loaded = _loaded_after_importing(["gcs.station", "gcs.client", "gcs.plans", "gcs.commands", "gcs.shell",
                                      "gcs.cli", "gcs.mapserver", "gcs.track"])
    assert "gcs" in loaded and "link" in loaded
    assert "vehicle" not in loaded and "sim" not in loaded


def test_the_vehicle_runs_without_the_simulator():
    loaded = _loaded_after_importing(["vehicle.app", "vehicle.keystore", "vehicle.epochs",
                                      "vehicle.companion.app", "vehicle.companion.cli"])
    assert "vehicle" in loaded and "sim" not in loaded
