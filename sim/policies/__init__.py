"""Link-loss policies a trial can fly (docs/architecture.md §9): returnlink itself and the baselines it is compared
against.

Every policy runs on the same vehicle and simulator, so only the policy differs between paired trials: the
lease book, its COMMS_LOST trigger, telemetry, the radio and the operator's script are the same; a baseline is a
``vehicle.contingency.Contingency`` that drives the return-service lease instead of the scenario's return plan.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the command line reads the names without loading the vehicle
    from vehicle.contingency import Contingency

NATIVE_POLICIES: tuple[str, ...] = ("returnlink", "hold", "rtl", "smartrtl", "backup")
# the real ArduPilot firmware's own failsafes (docs/architecture.md §10), flown only by vehicle ``ardurover``
FAILSAFE_POLICIES: tuple[str, ...] = ("ardupilot-hold", "ardupilot-rtl", "ardupilot-smartrtl")
# returnlink as a companion computer beside the same firmware (§11), its ground link through the scenario's radio
COMPANION_POLICY = "companion"
# returnlink's Lua applet aboard the same firmware (docs/architecture.md §11.3): no returnlink process at all, the
# firmware's GCS failsafe its backstop
APPLET_POLICY = "applet"
FIRMWARE_POLICIES: tuple[str, ...] = (*FAILSAFE_POLICIES, COMPANION_POLICY, APPLET_POLICY)
# PX4's own data-link failsafe (NAV_DLL_ACT 1 Hold, 2 Return; docs/architecture.md §10.1), flown only by ``px4rover``
# (``companion`` flies beside PX4 too, §11.2: it is the one policy both autopilot vehicles fly)
PX4_FAILSAFE_POLICIES: tuple[str, ...] = ("px4-hold", "px4-return")
POLICY_NAMES: tuple[str, ...] = NATIVE_POLICIES + FIRMWARE_POLICIES + PX4_FAILSAFE_POLICIES
DEFAULT_POLICY = "returnlink"
FIRMWARE_VEHICLE = "ardurover"
DEFAULT_FIRMWARE_POLICY = "ardupilot-smartrtl"
PX4_VEHICLE = "px4rover"
DEFAULT_PX4_POLICY = "px4-return"
AUTOPILOT_VEHICLES: tuple[str, ...] = (FIRMWARE_VEHICLE, PX4_VEHICLE)  # the real autopilots: no returnlink aboard


def vehicle_for(policy: str) -> str | None:
    """The one vehicle that flies ``policy``, or None for a native policy (flown by rover and legged)."""
    if policy in FIRMWARE_POLICIES:
        return FIRMWARE_VEHICLE
    if policy in PX4_FAILSAFE_POLICIES:
        return PX4_VEHICLE
    return None


def flies(policy: str, vehicle: str) -> bool:
    """Whether ``vehicle`` can fly ``policy``: the ArduPilot firmware's failsafes need that firmware, PX4's failsafes
    need PX4, the companion flies beside either, and neither autopilot has returnlink onboard to fly the native
    policies with."""
    if policy == COMPANION_POLICY:
        return vehicle in AUTOPILOT_VEHICLES
    needs = vehicle_for(policy)
    return vehicle == needs if needs is not None else vehicle not in AUTOPILOT_VEHICLES


def check_policy(name: str) -> str:
    """The name of a policy the native vehicle flies, or ValueError saying why not."""
    if name in FIRMWARE_POLICIES:
        if name == APPLET_POLICY:
            raise ValueError(f"policy {name!r} is returnlink's Lua applet aboard the ArduPilot firmware: fly it with "
                             f"vehicle {FIRMWARE_VEHICLE!r}")
        if name == COMPANION_POLICY:
            raise ValueError(f"policy {name!r} is returnlink companion beside a real autopilot: fly it with vehicle "
                             f"{FIRMWARE_VEHICLE!r} or {PX4_VEHICLE!r}")
        raise ValueError(f"policy {name!r} is the ArduPilot firmware's own failsafe: fly it with vehicle "
                         f"{FIRMWARE_VEHICLE!r}")
    if name in PX4_FAILSAFE_POLICIES:
        raise ValueError(f"policy {name!r} is PX4's own data-link failsafe: fly it with vehicle {PX4_VEHICLE!r}")
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
