"""Link-loss policies a trial can fly (docs/architecture.md §9): returnlink itself and the baselines it is compared
against.

Every policy runs on the same vehicle and simulator, so only the policy differs between paired trials: the
lease book, its COMMS_LOST trigger, telemetry, the radio and the operator's script are the same; a baseline is a
``vehicle.contingency.Contingency`` that drives the return-service lease instead of the scenario's return plan.

Which vehicle flies which policy is the plant registry's (``sim.registry``); the names below are read from it and
kept here for the modules and tests that import them from this package.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from sim import registry
from sim.registry import AUTOPILOT_VEHICLES, DEFAULT_POLICY, POLICY_NAMES, flies, vehicle_for

if TYPE_CHECKING:  # the command line reads the names without loading the vehicle
    from vehicle.contingency import Contingency

NATIVE_POLICIES: tuple[str, ...] = registry.NATIVE_PLANT.policies
# the real ArduPilot firmware's own failsafes (docs/architecture.md §10), flown only by vehicle ``ardurover``
FAILSAFE_POLICIES: tuple[str, ...] = registry.FIRMWARE_PLANT.policies
# PX4's own data-link failsafe (NAV_DLL_ACT 1 Hold, 2 Return; docs/architecture.md §10.1), flown only by ``px4rover``
PX4_FAILSAFE_POLICIES: tuple[str, ...] = registry.PX4_PLANT.policies
(COMPANION_POLICY,) = registry.COMPANION_PLANT.policies  # returnlink beside either autopilot (§11, §11.2)
(APPLET_POLICY,) = registry.APPLET_PLANT.policies  # returnlink's Lua applet aboard the ArduPilot firmware (§11.3)

__all__ = ["APPLET_POLICY", "AUTOPILOT_VEHICLES", "COMPANION_POLICY", "DEFAULT_POLICY", "FAILSAFE_POLICIES",
           "NATIVE_POLICIES", "POLICY_NAMES", "PX4_FAILSAFE_POLICIES", "check_policy", "flies", "make_policy",
           "vehicle_for"]


def check_policy(name: str) -> str:
    """The name of a policy the native vehicle flies, or ValueError saying why not (``sim.registry``)."""
    return registry.check_native_policy(name)


def _hold() -> Contingency:
    from sim.policies import hold

    return hold.Hold()


def _rtl() -> Contingency:
    from sim.policies import rtl

    return rtl.StraightRTL()


def _smartrtl() -> Contingency:
    from sim.policies import smartrtl

    return smartrtl.SmartRTL()


def _backup() -> Contingency:
    from sim.policies import backup

    return backup.Backup()


# the baselines the native vehicle flies instead of its return plan; returnlink itself is absent (its own plan)
BASELINES: dict[str, Callable[[], Contingency]] = {"hold": _hold, "rtl": _rtl, "smartrtl": _smartrtl,
                                                   "backup": _backup}


def make_policy(name: str) -> Contingency | None:
    """The behaviour to inject into the vehicle for policy ``name``: None for returnlink (its own return plan)."""
    check_policy(name)
    make = BASELINES.get(name)
    return make() if make is not None else None
