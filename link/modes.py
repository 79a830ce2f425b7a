"""Flight-mode numbers as ground stations send and read them: PX4's custom_mode encoding and ArduPilot Rover's.

Neither is in the MAVLink dialect (they are each autopilot's own), and both ends need them: the vehicle shows its
state in PX4's encoding and accepts both (``vehicle/modes.py``), the ground station asks for HOLD in PX4's.
"""

from __future__ import annotations

# PX4 custom_mode: main mode in bits 16-23, sub mode in bits 24-31
PX4_MANUAL, PX4_POSCTL, PX4_AUTO = 1, 3, 4  # main modes
PX4_AUTO_LOITER, PX4_AUTO_MISSION, PX4_AUTO_RTL = 3, 4, 5  # sub modes of AUTO
# ArduPilot Rover mode numbers
AP_MANUAL, AP_ACRO, AP_STEERING, AP_HOLD, AP_AUTO, AP_RTL, AP_SMART_RTL = 0, 1, 3, 4, 10, 11, 12


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT.custom_mode of a PX4 main and sub mode."""
    return (main << 16) | (sub << 24)


def px4_parts(custom_mode: int) -> tuple[int, int]:
    """(main, sub) of a PX4 custom_mode."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
