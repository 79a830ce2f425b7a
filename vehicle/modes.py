"""Flight modes as ground stations speak them: PX4's custom_mode encoding and ArduPilot Rover's numbers.

The vehicle shows its state in the heartbeat as a PX4 custom mode (POSCTL while teleoperated, AUTO_RTL while
returning, AUTO_LOITER while holding), which MAVSDK and QGroundControl read for a generic autopilot; it accepts
DO_SET_MODE / SET_MODE in both encodings, so MAVSDK's ``return_to_launch()`` and MAVProxy's ``mode RTL`` work.
"""

from __future__ import annotations

from vehicle.app import State

CUSTOM_MODE_ENABLED = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
# PX4 custom_mode: main mode in bits 16-23, sub mode in bits 24-31
PX4_MANUAL, PX4_POSCTL, PX4_AUTO = 1, 3, 4
PX4_AUTO_LOITER, PX4_AUTO_MISSION, PX4_AUTO_RTL = 3, 4, 5
# ArduPilot Rover mode numbers
AP_MANUAL, AP_ACRO, AP_STEERING, AP_HOLD, AP_AUTO, AP_RTL, AP_SMART_RTL = 0, 1, 3, 4, 10, 11, 12


def custom_mode(state: int, holding: bool) -> int:
    """The PX4 custom_mode that shows a RETURNLINK_STATE."""
    if state == State.TELEOP and not holding:
        return PX4_POSCTL << 16
    if state == State.RETURNING:
        return (PX4_AUTO << 16) | (PX4_AUTO_RTL << 24)
    if state == State.NAVIGATING:
        return (PX4_AUTO << 16) | (PX4_AUTO_MISSION << 24)
    return (PX4_AUTO << 16) | (PX4_AUTO_LOITER << 24)


def decode_mode(base: int, custom: int, sub: int) -> str | None:
    """DO_SET_MODE in the PX4 encoding (main/sub) or the ArduPilot Rover numbering -> HOLD / RTL / MANUAL."""
    if not base & CUSTOM_MODE_ENABLED:
        return None
    if custom == PX4_AUTO:
        if sub in (PX4_AUTO_RTL, PX4_AUTO_MISSION):
            return "RTL"
        if sub in (PX4_AUTO_LOITER, 0):
            return "HOLD"  # PX4 AUTO/LOITER, or ArduPilot Rover HOLD (4 with sub 0)
        return None
    if custom in (PX4_MANUAL, PX4_POSCTL, AP_MANUAL, AP_STEERING):
        return "MANUAL"
    if custom in (AP_RTL, AP_SMART_RTL, AP_AUTO):
        return "RTL"
    return None
