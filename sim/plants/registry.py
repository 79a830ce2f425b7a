"""The plant classes, paired with the registry's entries (``sim.registry``): which class flies a vehicle and a
policy.

``sim.registry`` says what each plant flies as plain data, so the command line and the plants can read it without
loading each other; this module is the one place that holds the classes. Each is reached by importing its module
(``from sim.plants import firmware``) the first time it is asked for, never by a name in a string, so flying the
native rover loads neither the ArduPilot nor the PX4 machinery.
"""

from __future__ import annotations

from collections.abc import Callable

from sim import registry


def _native() -> type:
    from sim.plants import native

    return native.NativePlant


def _firmware() -> type:
    from sim.plants import firmware

    return firmware.FirmwarePlant


def _companion() -> type:
    from sim.plants import companion

    return companion.CompanionPlant


def _applet() -> type:
    from sim.plants import applet

    return applet.AppletPlant


def _px4() -> type:
    from sim.plants import px4

    return px4.PX4Plant


def _px4_companion() -> type:
    from sim.plants import px4_companion

    return px4_companion.PX4CompanionPlant


# every entry of the registry and the import that gives its class
CLASSES: tuple[tuple[registry.Entry, Callable[[], type]], ...] = (
    (registry.NATIVE_PLANT, _native),
    (registry.FIRMWARE_PLANT, _firmware),
    (registry.COMPANION_PLANT, _companion),
    (registry.APPLET_PLANT, _applet),
    (registry.PX4_PLANT, _px4),
    (registry.PX4_COMPANION_PLANT, _px4_companion),
)


def plant_class(entry: registry.Entry) -> type:
    """The class of the registry's plant ``entry``."""
    return next(load for e, load in CLASSES if e is entry)()


def plant_for(vehicle: str, policy: str) -> type:
    """The plant class that flies ``policy`` on ``vehicle`` (``sim.registry.plant_entry``: for a pair no plant
    flies, the vehicle's own plant, which refuses the policy itself, saying why)."""
    return plant_class(registry.plant_entry(vehicle, policy))
