"""One registry of plants (docs/architecture.md §2, "three faces, one registry"): which vehicle kinds there are,
which link-loss policies each flies, which plant flies a pair, what outside program it needs and its defaults.

The command line (``--vehicle`` / ``--policy`` choices and their errors), sweep specs, ``sim serve``, the trial
runner and the plants themselves ask this module; nothing else compares a vehicle or policy name with a literal,
so a new plant is one entry here and its own module, as ArduPilot registers a SITL backend once and never asks
its name again.

The table is plain data, cheap to import and importing nothing of the project, so the plants, the baselines and
the scenario reader read it too without a circle: the command line builds its parser from it without loading
pymunk or the vehicle (``sim.plants`` costs seconds). The plant classes themselves are paired with these entries in
``sim.plants.registry``, each reached by importing its module, never by a name in a string.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Outside(Enum):
    """The outside program a vehicle kind needs: none (returnlink's own vehicle aboard), the ArduPilot Rover
    firmware (docs/architecture.md §10) or PX4 (§10.1). ``label`` names it in messages; ``option`` is the
    keyword that hands its binary or directory to ``sim.runner.Run`` and the plant."""

    NONE = ("", "")
    ARDUPILOT = ("the ArduPilot firmware", "firmware")
    PX4 = ("PX4", "px4")

    def __init__(self, label: str, option: str) -> None:
        self.label = label
        self.option = option

    def locate(self, given: str | None = None):
        """The program's binary (ArduPilot) or directory (PX4) from ``given``, else its environment variable, else
        its default place; raises the locator's own not-found error. None for a vehicle that needs none."""
        if self is Outside.ARDUPILOT:
            from sim.firmware import locate

            return locate.find_firmware(given)
        if self is Outside.PX4:
            from sim.px4 import locate as px4_locate

            return px4_locate.find_px4(given)
        return None

    @property
    def env(self) -> str | None:
        """The environment variable a worker finds the program by (None: no program)."""
        if self is Outside.ARDUPILOT:
            from sim.firmware import locate

            return locate.ENV
        if self is Outside.PX4:
            from sim.px4 import locate as px4_locate

            return px4_locate.ENV
        return None


@dataclass(frozen=True)
class Policy:
    """A link-loss policy (docs/architecture.md §9-§11). ``what`` completes "policy X is ..." where a vehicle
    cannot fly it; ``need`` completes "policy X ..." on the command line (empty: "needs" the vehicle's program);
    ``fs_action`` is ArduPilot's FS_ACTION for a policy flown on that firmware (its GCS failsafe, or the backstop
    behind returnlink beside or aboard it); ``nav_dll_act`` and ``com_obl_rc_act`` are PX4's data-link and
    Offboard-loss actions for a policy that is PX4's own failsafe (Hold 1 / 5, Return 2 / 3); ``beside``:
    returnlink runs as a companion beside the autopilot, whose parameters must then pass the companion's own check
    and whose rover carries rangefinders for it; ``aboard``: returnlink runs inside the autopilot itself (the Lua
    applet)."""

    name: str
    what: str = ""
    need: str = ""
    fs_action: int | None = None
    nav_dll_act: int | None = None
    com_obl_rc_act: int | None = None
    beside: bool = False
    aboard: bool = False


@dataclass(frozen=True)
class Vehicle:
    """A vehicle kind: the outside program it needs, the policy it flies unless told, and for an autopilot the
    sentence the command line says when asked for a policy it does not fly."""

    name: str
    outside: Outside
    default_policy: str
    flies_text: str = ""


@dataclass(frozen=True)
class Entry:
    """One plant: the vehicle kinds and policies it flies (its class declares the same as ``kind`` and
    ``policies``, read from here)."""

    name: str
    vehicles: tuple[str, ...]
    policies: tuple[str, ...]


# ----- the policies, in the order the command line and the reports list them ----------------------------------
NATIVE = "returnlink"  # the scenario's own return plan
_ARDUPILOT_FAILSAFE = "the ArduPilot firmware's own failsafe"
_PX4_FAILSAFE = "PX4's own data-link failsafe"
POLICIES: tuple[Policy, ...] = (
    Policy(NATIVE), Policy("hold"), Policy("rtl"), Policy("smartrtl"), Policy("backup"),
    Policy("ardupilot-hold", _ARDUPILOT_FAILSAFE, fs_action=2),
    Policy("ardupilot-rtl", _ARDUPILOT_FAILSAFE, fs_action=1),
    Policy("ardupilot-smartrtl", _ARDUPILOT_FAILSAFE, fs_action=4),
    # returnlink as a companion computer beside the firmware or PX4 (§11, §11.2): the firmware's Hold its backstop
    Policy("companion", "returnlink companion beside a real autopilot", "runs beside a real autopilot",
           fs_action=2, beside=True),
    # returnlink's Lua applet aboard the ArduPilot firmware (§11.3): no returnlink process, the GCS failsafe its
    # backstop
    Policy("applet", "returnlink's Lua applet aboard the ArduPilot firmware", fs_action=2, aboard=True),
    Policy("px4-hold", _PX4_FAILSAFE, nav_dll_act=1, com_obl_rc_act=5),
    Policy("px4-return", _PX4_FAILSAFE, nav_dll_act=2, com_obl_rc_act=3),
)
BY_POLICY: dict[str, Policy] = {p.name: p for p in POLICIES}
POLICY_NAMES: tuple[str, ...] = tuple(BY_POLICY)
DEFAULT_POLICY = NATIVE

# ----- the vehicle kinds -----------------------------------------------------------------------------------------
VEHICLES_TABLE: tuple[Vehicle, ...] = (
    Vehicle("rover", Outside.NONE, NATIVE),
    Vehicle("legged", Outside.NONE, NATIVE),
    Vehicle("ardurover", Outside.ARDUPILOT, "ardupilot-smartrtl",
            "the ArduPilot firmware's own failsafes, returnlink beside it or the Lua applet in it: --policy "
            "ardupilot-hold, ardupilot-rtl, ardupilot-smartrtl, companion or applet"),
    Vehicle("px4rover", Outside.PX4, "px4-return",
            "PX4's own data-link failsafe or returnlink beside it: --policy px4-hold or px4-return or companion"),
)
BY_VEHICLE: dict[str, Vehicle] = {v.name: v for v in VEHICLES_TABLE}
VEHICLES: tuple[str, ...] = tuple(BY_VEHICLE)
NATIVE_VEHICLES: tuple[str, ...] = tuple(v.name for v in VEHICLES_TABLE if v.outside is Outside.NONE)
AUTOPILOT_VEHICLES: tuple[str, ...] = tuple(v.name for v in VEHICLES_TABLE if v.outside is not Outside.NONE)


# ----- the plants: what each flies (``sim.plants.registry`` pairs each with its class, imported) ---------------
NATIVE_PLANT = Entry("native", NATIVE_VEHICLES, ("returnlink", "hold", "rtl", "smartrtl", "backup"))
FIRMWARE_PLANT = Entry("firmware", ("ardurover",), ("ardupilot-hold", "ardupilot-rtl", "ardupilot-smartrtl"))
COMPANION_PLANT = Entry("companion", ("ardurover",), ("companion",))
APPLET_PLANT = Entry("applet", ("ardurover",), ("applet",))
PX4_PLANT = Entry("px4", ("px4rover",), ("px4-hold", "px4-return"))
PX4_COMPANION_PLANT = Entry("px4-companion", ("px4rover",), ("companion",))
PLANTS: tuple[Entry, ...] = (NATIVE_PLANT, FIRMWARE_PLANT, COMPANION_PLANT, APPLET_PLANT, PX4_PLANT,
                             PX4_COMPANION_PLANT)


def flies(policy: str, vehicle: str) -> bool:
    """Whether some plant flies ``policy`` on ``vehicle``."""
    return any(vehicle in e.vehicles and policy in e.policies for e in PLANTS)


def needing(program: Outside) -> tuple[str, ...]:
    """The vehicle kinds that need ``program``."""
    return tuple(v.name for v in VEHICLES_TABLE if v.outside is program)


def vehicles_for(policy: str) -> tuple[str, ...]:
    """Every vehicle kind that flies ``policy``, in the registry's order."""
    return tuple(v for v in VEHICLES if flies(policy, v))


def vehicle_for(policy: str) -> str | None:
    """The one vehicle that flies ``policy``, or None when it is a native policy (flown by rover and legged)
    or none; the companion's first autopilot, as before the registry."""
    found = vehicles_for(policy)
    return None if not found or set(found) <= set(NATIVE_VEHICLES) else found[0]


def outside(vehicle: str) -> Outside:
    """The outside program ``vehicle`` needs (Outside.NONE for an unknown kind: the plant refuses it itself)."""
    v = BY_VEHICLE.get(vehicle)
    return v.outside if v is not None else Outside.NONE


def default_policy(vehicle: str) -> str:
    """What ``vehicle`` flies when no policy is named."""
    v = BY_VEHICLE.get(vehicle)
    return v.default_policy if v is not None else DEFAULT_POLICY


def plant_entry(vehicle: str, policy: str) -> Entry:
    """The plant that flies ``policy`` on ``vehicle``; for a pair no plant flies, the plant of the vehicle's
    default policy, which refuses the policy itself, saying why (the native plant for a kind it does not know)."""
    for e in PLANTS:
        if vehicle in e.vehicles and policy in e.policies:
            return e
    fallback = default_policy(vehicle)
    return next(e for e in PLANTS if (vehicle in e.vehicles or vehicle not in VEHICLES) and fallback in e.policies)


def check_native_policy(name: str) -> str:
    """The name of a policy a native vehicle flies, or ValueError saying which vehicle flies it instead."""
    if flies(name, NATIVE_VEHICLES[0]):
        return name
    if name not in BY_POLICY:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(POLICY_NAMES)}")
    vehicles = " or ".join(repr(v) for v in vehicles_for(name))
    raise ValueError(f"policy {name!r} is {BY_POLICY[name].what}: fly it with vehicle {vehicles}")


def why_not(policy: str, vehicle: str) -> str:
    """Why ``vehicle`` cannot fly ``policy``, as the command line says it: an autopilot names what it flies, a
    native vehicle names the vehicle the policy needs."""
    kind = BY_VEHICLE.get(vehicle)
    if kind is not None and kind.flies_text:
        return f"vehicle {vehicle} flies {kind.flies_text} (got {policy})"
    found = vehicles_for(policy)
    if not found:
        return f"unknown policy {policy}; known: {', '.join(POLICY_NAMES)}"
    need = BY_POLICY[policy].need or f"needs {outside(found[0]).label}"
    return f"policy {policy} {need}: use --vehicle {' or '.join(found)}"


def spec_need(policy: str) -> str:
    """What a sweep spec lacks when no listed vehicle flies ``policy``: "policy P needs {this} in vehicles"."""
    found = vehicles_for(policy)
    if set(found) <= set(NATIVE_VEHICLES):
        return f"a native vehicle ({', '.join(NATIVE_VEHICLES)})"
    return "vehicle " + " or ".join(repr(v) for v in found)


def autopilot_policies() -> tuple[str, ...]:
    """The policies only a real autopilot flies (``sim serve``'s ``--policy`` choices)."""
    return tuple(p for p in POLICY_NAMES if not any(flies(p, v) for v in NATIVE_VEHICLES))
