"""The §7 figures of a companion run (``sim.firmware.companion.CompanionRun``), plus ``firmware`` and
``firmware_modes`` as for every firmware run.

The companion flies the native vehicle's lease book, trail and return service, and the run keeps the native
runner's record of them, so every key is computed by the native rules (``sim.metrics``), none is null for want
of a lease: return start and end from its LEASE_EVENTs, the reaction from the moment its trigger's condition
became true, the trail it laid, the stale commands (the vehicle's own guard, plus the run's audit of every frame
the router forwarded to the firmware), the scenario's whole verdict. Positions are in the true frame; the
estimate is the companion's (which fuses the autopilot's EKF), in the true frame through its origin.
"""

from __future__ import annotations

from sim import metrics as native
from sim.firmware.companion import CompanionRun
from sim.firmware.metrics import FIRMWARE_KEYS
from sim.firmware.process import FirmwareError


def compute(run: CompanionRun) -> dict:
    if run.vehicle is None:
        raise FirmwareError(f"the companion never started: the firmware reported no position estimate in "
                            f"{run.t:.1f} simulated s")
    m = native.compute(run)
    m["frames"] = {**m["frames"], "estimator_rmse_m": "true (the companion's estimate, through the firmware's "
                   "EKF origin: the scenario's start)"}
    m["firmware"] = run.link.tap.version
    m["firmware_modes"] = run.firmware_modes
    assert tuple(m) == FIRMWARE_KEYS
    return m


def summary(run: CompanionRun, m: dict) -> str:
    lines = native.summary(run, m).splitlines()
    c = run.companion.counters
    extra = [f"  firmware {m['firmware']} (booted in {run.link.boot_s:.1f} simulated s before scenario time 0), "
             f"returnlink companion on its telemetry port",
             f"  the companion forwarded {c['forwarded']} ground frames to the firmware, refused {c['refused']}, "
             f"relayed {c['relayed']} of the firmware's to the ground; keepalives {run.companion.driver.keepalives}"]
    modes = ["  firmware modes:"] + [f"    {e['t']:7.2f} s  {e['mode']}" for e in m["firmware_modes"]]
    notes = [f"  note: {n}" for n in run.notes]
    return "\n".join([lines[0], *extra, *lines[1:-1], *modes, *notes, lines[-1]])
