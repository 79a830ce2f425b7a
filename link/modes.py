"""Flight-mode numbers as the autopilots ground stations know put them on the wire.

A ground station asks for a mode (DO_SET_MODE, SET_MODE) in the numbering of the autopilot it believes it talks to:
PX4 packs a main mode and a sub mode into ``custom_mode`` (bits 16-23 and 24-31), ArduPilot Rover sends its mode
number. Neither numbering is in a MAVLink XML (each is its autopilot's own), so they are named here once, for the
vehicle (which shows its state in the PX4 encoding and accepts both, ``vehicle/modes.py``) and for any station.
"""

from __future__ import annotations

# PX4 main modes (custom_mode bits 16-23)
PX4_MANUAL, PX4_POSCTL, PX4_AUTO = 1, 3, 4
# PX4 sub modes of AUTO (custom_mode bits 24-31)
PX4_AUTO_LOITER, PX4_AUTO_MISSION, PX4_AUTO_RTL = 3, 4, 5
# ArduPilot Rover mode numbers (custom_mode as a whole)
AP_MANUAL, AP_ACRO, AP_STEERING, AP_HOLD, AP_AUTO, AP_RTL, AP_SMART_RTL = 0, 1, 3, 4, 10, 11, 12


def px4_mode(main: int, sub: int = 0) -> int:
    """The custom_mode of PX4 main mode ``main`` and sub mode ``sub``."""
    return (main << 16) | (sub << 24)


def px4_parts(custom_mode: int) -> tuple[int, int]:
    """(main, sub) of a PX4 custom_mode."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
