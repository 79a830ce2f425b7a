"""Who a component is and what mode it is in: HEARTBEAT and the standard modes microservice (docs/architecture.md §4).

The heartbeat names the component's type and autopilot (a native vehicle: its robot's MAV_TYPE and
MAV_AUTOPILOT_GENERIC; a companion computer: ONBOARD_CONTROLLER and INVALID, docs/architecture.md §11), whether it
is armed, and its state as a PX4 custom mode (``vehicle.modes``). CURRENT_MODE and AVAILABLE_MODES (MAVLink's
development.xml) let ground stations that know the standard modes name them without guessing from the autopilot
type. The returnlink dialect (common.xml + lease messages) does not include those two messages: they are encoded
with pymavlink's own development module, so the dialect contract stays unchanged."""

from __future__ import annotations

from pymavlink.dialects.v20 import development as modes_wire

from link.wire import MAVLINK_VERSION
from vehicle.lease_terms import State
from vehicle.modes import AVAILABLE_MODES, custom_mode, standard_mode
from vehicle.port import Snapshot
from vehicle.services.base import mav

MSG_ID_AVAILABLE_MODES = modes_wire.MAVLINK_MSG_ID_AVAILABLE_MODES
MSG_ID_CURRENT_MODE = modes_wire.MAVLINK_MSG_ID_CURRENT_MODE
AUTO_STATES = (State.RETURNING, State.NAVIGATING)  # shown with MAV_MODE_FLAG_AUTO_ENABLED


class Heartbeat:
    """The identity and mode reports of one component, sent through its encoder ``enc``.

    ``mav_type`` None: the robot's own (the status snapshot's ``mav_type``)."""

    def __init__(self, enc, vehicle: Snapshot, mav_type: int | None = None,
                 autopilot: int = mav.MAV_AUTOPILOT_GENERIC) -> None:
        self.mav = enc
        self.vehicle = vehicle
        self.mav_type = mav_type
        self.autopilot = autopilot

    def custom_mode(self) -> int:
        s = self.vehicle.status()
        return custom_mode(s.state, s.holding)

    def send(self, t: float) -> None:
        """One HEARTBEAT (1 Hz, and on request)."""
        s = self.vehicle.status()
        base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if s.armed:
            base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        state = s.state
        if state == State.TELEOP:
            base |= mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        elif state in AUTO_STATES:
            base |= mav.MAV_MODE_FLAG_AUTO_ENABLED
        system_status = mav.MAV_STATE_ACTIVE if s.armed else mav.MAV_STATE_STANDBY
        mav_type = s.mav_type if self.mav_type is None else self.mav_type
        # the message object straight to ``send``, as ``heartbeat_send`` does after ``heartbeat_encode``
        self.mav.send(mav.MAVLink_heartbeat_message(mav_type, self.autopilot, base, custom_mode(state, s.holding),
                                                    system_status, MAVLINK_VERSION))

    def current_mode(self, t: float) -> None:
        """CURRENT_MODE: sent on every mode change and on request."""
        mode = self.custom_mode()
        self.mav.send(modes_wire.MAVLink_current_mode_message(standard_mode(mode), mode, 0))

    def available_modes(self, index: int) -> bool:
        """AVAILABLE_MODES for mode ``index`` (1-based), or every mode for 0; False for an index out of range."""
        n = len(AVAILABLE_MODES)
        if not 0 <= index <= n:
            return False
        for k in range(1, n + 1) if index == 0 else (index,):
            m = AVAILABLE_MODES[k - 1]
            self.mav.send(modes_wire.MAVLink_available_modes_message(n, k, m.standard, m.custom, 0, m.name.encode()))
        return True
