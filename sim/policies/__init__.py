"""Link-loss policies a trial can fly (docs/architecture.md §9): returnlink itself and the baselines it is compared
against.

Every policy runs on the same vehicle and simulator, so only the policy differs between paired trials: the
lease book, its COMMS_LOST trigger, telemetry, the radio and the operator's script are the same; a baseline is a
``vehicle.app.Contingency`` that drives the return-service lease instead of the scenario's return plan.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the command line reads the names without loading the vehicle
    from vehicle.app import Contingency

NATIVE_POLICIES: tuple[str, ...] = ("returnlink", "hold", "rtl", "smartrtl", "backup")
# the real ArduPilot firmware's own failsafes (docs/architecture.md §10), flown only by vehicle ``ardurover``
FAILSAFE_POLICIES: tuple[str, ...] = ("ardupilot-hold", "ardupilot-rtl", "ardupilot-smartrtl")
# returnlink as a companion computer beside the same firmware (§11), its ground link through the scenario's radio
COMPANION_POLICY = "companion"
FIRMWARE_POLICIES: tuple[str, ...] = (*FAILSAFE_POLICIES, COMPANION_POLICY)
POLICY_NAMES: tuple[str, ...] = NATIVE_POLICIES + FIRMWARE_POLICIES
DEFAULT_POLICY = "returnlink"
FIRMWARE_VEHICLE = "ardurover"
DEFAULT_FIRMWARE_POLICY = "ardupilot-smartrtl"


def flies(policy: str, vehicle: str) -> bool:
    """Whether ``vehicle`` can fly ``policy``: the firmware's failsafes and the companion need the firmware, and the
    firmware has no returnlink onboard to fly the native policies with."""
    return (policy in FIRMWARE_POLICIES) == (vehicle == FIRMWARE_VEHICLE)


def check_policy(name: str) -> str:
    """The name of a policy the native vehicle flies, or ValueError saying why not."""
    if name in FIRMWARE_POLICIES:
        what = "returnlink companion beside the ArduPilot firmware" if name == COMPANION_POLICY else \
            "the ArduPilot firmware's own failsafe"
        raise ValueError(f"policy {name!r} is {what}: fly it with vehicle {FIRMWARE_VEHICLE!r}")
    if name not in NATIVE_POLICIES:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(POLICY_NAMES)}")
    return name


def make_policy(name: str) -> Contingency | None:
    """The behaviour to inject into the vehicle for policy ``name``: None for returnlink (its own return plan)."""
    check_policy(name)
    if name == "hold":
        from sim.policies.hold import Hold

        return Hold()
    if name == "rtl":
        from sim.policies.rtl import StraightRTL

        return StraightRTL()
    if name == "smartrtl":
        from sim.policies.smartrtl import SmartRTL

        return SmartRTL()
    if name == "backup":
        from sim.policies.backup import Backup

        return Backup()
    return None
