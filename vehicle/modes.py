"""Flight modes as ground stations speak them: PX4's custom_mode encoding and ArduPilot Rover's numbers.

The vehicle shows its state in the heartbeat as a PX4 custom mode (POSCTL while teleoperated, AUTO_RTL while
returning, AUTO_LOITER while holding), which MAVSDK and QGroundControl read for a generic autopilot; it accepts
DO_SET_MODE / SET_MODE in both encodings, so MAVSDK's ``return_to_launch()`` and MAVProxy's ``mode RTL`` work.
"""

from __future__ import annotations

from dataclasses import dataclass

from link import dialect
from link.modes import (  # noqa: F401 - the mode numbers, re-exported for the vehicle's readers
    AP_ACRO,
    AP_AUTO,
    AP_HOLD,
    AP_MANUAL,
    AP_RTL,
    AP_SMART_RTL,
    AP_STEERING,
    PX4_AUTO,
    PX4_AUTO_LOITER,
    PX4_AUTO_MISSION,
    PX4_AUTO_RTL,
    PX4_MANUAL,
    PX4_POSCTL,
)
from vehicle.lease_terms import State

CUSTOM_MODE_ENABLED = dialect.load().MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


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


# ----- the standard modes microservice (AVAILABLE_MODES / CURRENT_MODE, MAVLink development.xml) -------------------
# Ground stations that know the microservice (QGroundControl, recent MAVProxy and MAVSDK) list and name the modes
# from these answers instead of guessing from the autopilot type, so the vehicle can stay MAV_AUTOPILOT_GENERIC
# with PX4-encoded custom modes without claiming to be PX4. Standard modes carry no name (the ground station names
# them); the one mode with no standard equivalent, teleoperation under the operator lease, is named.
STANDARD_NON_STANDARD, STANDARD_POSITION_HOLD, STANDARD_SAFE_RECOVERY, STANDARD_MISSION = 0, 1, 5, 6


@dataclass(frozen=True)
class ModeInfo:
    standard: int  # MAV_STANDARD_MODE
    custom: int  # the heartbeat's custom_mode while in this mode
    name: str  # empty for standard modes


AVAILABLE_MODES: tuple[ModeInfo, ...] = (
    ModeInfo(STANDARD_NON_STANDARD, PX4_POSCTL << 16, "TELEOP"),
    ModeInfo(STANDARD_POSITION_HOLD, (PX4_AUTO << 16) | (PX4_AUTO_LOITER << 24), ""),
    ModeInfo(STANDARD_SAFE_RECOVERY, (PX4_AUTO << 16) | (PX4_AUTO_RTL << 24), ""),
    ModeInfo(STANDARD_MISSION, (PX4_AUTO << 16) | (PX4_AUTO_MISSION << 24), ""),
)


def standard_mode(custom: int) -> int:
    """The MAV_STANDARD_MODE of a heartbeat custom_mode (NON_STANDARD when none fits)."""
    for m in AVAILABLE_MODES:
        if m.custom == custom:
            return m.standard
    return STANDARD_NON_STANDARD
