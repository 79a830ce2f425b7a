"""returnlink as a Lua applet aboard an unmodified ArduPilot Rover (docs/architecture.md §11.3, docs/applet.md).

``returnlink.lua`` is the whole applet: an owner copies it to ``APM/scripts/`` on the flight controller's SD card.
Nothing in Python runs aboard; this package only ships the file and says where it lies (the simulator copies it
into the SITL firmware's ``scripts/`` folder for ``--policy applet``).
"""

from __future__ import annotations

from pathlib import Path

SCRIPT = Path(__file__).with_name("returnlink.lua")
PREFIX = "RLNK_"  # its parameter table's prefix (param:add_table)
TEXT_PREFIX = "RLNK: "  # every STATUSTEXT it sends begins so

__all__ = ["PREFIX", "SCRIPT", "TEXT_PREFIX"]
