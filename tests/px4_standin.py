"""A scripted PX4 rover stand-in for the companion's fast tests (docs/architecture.md §11.2).

``FakePX4`` answers the way PX4's rover was read (``vehicle.companion.px4``) and measured to: its HEARTBEAT says
autopilot 12 and ground rover, custom_mode main/sub; DO_SET_MODE takes main and sub mode in params 2 and 3, and
Offboard is refused (DENIED) unless a setpoint arrived within COM_OF_LOSS_T; in Offboard a SET_POSITION_TARGET
velocity becomes speed (norm) and bearing, and a stream silent for COM_OF_LOSS_T ends Offboard in COM_OBL_RC_ACT
(5: Hold); parameters travel bytewise (INT32 bits in the float) and a PARAM_SET whose type is not the parameter's
own is ignored, as PX4 does. The real PX4 is tested in ``test_px4_companion.py``.
"""

from __future__ import annotations

import math
import struct

from pymavlink.dialects.v20 import ardupilotmega as apm

from tests.companion_rig import FakeAutopilot
from vehicle.companion.px4 import HOLD, OFFBOARD, custom_mode

POSCTL = custom_mode(3)
INT32, REAL32 = apm.MAV_PARAM_TYPE_INT32, apm.MAV_PARAM_TYPE_REAL32
PX4_DEFAULTS = {"NAV_DLL_ACT": (0, INT32), "COM_DL_LOSS_T": (10, INT32), "COM_OF_LOSS_T": (1.0, REAL32),
                "COM_OBL_RC_ACT": (0, INT32), "RO_YAW_P": (5.0, REAL32)}


def _bits(value: float, ptype: int) -> float:
    if ptype == INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return value


def _unbits(raw: float, ptype: int) -> float:
    if ptype == INT32:
        return float(struct.unpack("<i", struct.pack("<f", raw))[0])
    return raw


class FakePX4(FakeAutopilot):
    """PX4's rover as the companion meets it (see the module docstring). ``setpoints`` counts the setpoints it got
    (in any mode), ``refusals`` the Offboard requests it refused; ``locked`` names parameters that never change."""

    def __init__(self, sysid: int = 1, mav_type: int = apm.MAV_TYPE_GROUND_ROVER) -> None:
        super().__init__(sysid, apm.MAV_AUTOPILOT_PX4, mav_type)
        self.mode = HOLD
        self.typed = dict(PX4_DEFAULTS)  # name -> (value, MAV_PARAM_TYPE)
        self.setpoint_at = -math.inf
        self.setpoints = 0
        self.refusals = 0
        self.locked: set[str] = set()
        self.now = 0.0

    def param(self, name: str) -> float:
        return self.typed[name][0]

    def receive(self, data: bytes, t: float) -> None:
        self.now = t
        for m in self.parser.parse_buffer(data) or []:
            if m.get_type() == "BAD_DATA":
                continue
            self.received.append(m)
            if self.silent:
                continue
            kind = m.get_type()
            if kind == "COMMAND_LONG" and m.command == apm.MAV_CMD_DO_SET_MODE:
                mode = custom_mode(int(m.param2), int(m.param3))
                if mode == OFFBOARD and t - self.setpoint_at > self.param("COM_OF_LOSS_T"):
                    self.refusals += 1
                    self._ack(m, apm.MAV_RESULT_DENIED)
                else:
                    self.mode = mode
                    self._ack(m, apm.MAV_RESULT_ACCEPTED)
            elif kind == "COMMAND_LONG" and m.command == apm.MAV_CMD_COMPONENT_ARM_DISARM:
                self.armed = m.param1 >= 0.5
                self._ack(m, apm.MAV_RESULT_ACCEPTED)
            elif kind == "COMMAND_LONG":
                self._ack(m, apm.MAV_RESULT_ACCEPTED)
            elif kind == "SET_POSITION_TARGET_LOCAL_NED" and m.coordinate_frame in (apm.MAV_FRAME_LOCAL_NED,
                                                                                     apm.MAV_FRAME_BODY_NED):
                self.setpoint_at, self.setpoints = t, self.setpoints + 1
                if self.mode == OFFBOARD and not m.type_mask & 0b111000:
                    bearing = math.atan2(m.vy, m.vx) + (self.yaw if m.coordinate_frame == apm.MAV_FRAME_BODY_NED
                                                        else 0.0)
                    err = math.atan2(math.sin(bearing - self.yaw), math.cos(bearing - self.yaw))
                    # forward only; on the spot while more than RD_TRANS_DRV_TRN (20 deg) off the bearing
                    self.speed = math.hypot(m.vx, m.vy) if abs(err) < math.radians(20) else 0.0
                    self.yaw_rate = max(-3.0, min(3.0, self.param("RO_YAW_P") * err))
                    self.target_at = t
            elif kind in ("PARAM_REQUEST_READ", "PARAM_SET"):
                name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode()
                name = name.split("\x00")[0]
                if name not in self.typed:
                    continue  # PX4: "unknown param", no answer
                value, ptype = self.typed[name]
                if kind == "PARAM_SET":
                    if m.param_type != ptype:
                        continue  # PX4: "param types mismatch", no answer
                    if name not in self.locked:
                        self.typed[name] = (_unbits(m.param_value, ptype), ptype)
                value, ptype = self.typed[name]
                self._send(apm.MAVLink_param_value_message(name.encode(), _bits(value, ptype), ptype,
                                                           len(self.typed), 0))

    def _drives(self, t: float) -> bool:
        """PX4's Offboard loss first (Hold, or Position with COM_OBL_RC_ACT other than 5); then whether it follows
        its setpoint: Offboard and armed."""
        if self.mode == OFFBOARD and t - self.setpoint_at > self.param("COM_OF_LOSS_T"):
            self.mode = HOLD if self.param("COM_OBL_RC_ACT") == 5 else POSCTL
        return self.mode == OFFBOARD and self.armed

    def _estimator_report(self, ms: int):
        return apm.MAVLink_estimator_status_message(ms * 1000, 0x1F if self.ekf_ok else 0x03, 0, 0, 0, 0, 0, 0, 0, 0)
