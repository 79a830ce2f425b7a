"""What the companion believes of the autopilot (``vehicle.companion.observed``) and what the rules object answers
for it (``vehicle.companion.rules``): only the autopilot's own component is believed, each autopilot's estimator
status counts by its rules, parameters arrive in each autopilot's encoding."""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion.observed import EKF_POS_HORIZ_ABS, Observed, believe
from vehicle.companion.rules import ArduPilotRules, PX4Rules, rules_for
from vehicle.companion.targets import OffboardSteering, RoverSteering


def framed(msg, sysid: int = 1, compid: int = 1):
    """``msg`` as it arrives: packed by (sysid, compid) and parsed back (so it knows its sender)."""
    return apm.MAVLink(None, 0, 0).parse_buffer(bytes(msg.pack(apm.MAVLink(None, sysid, compid))))[0]


def estimator_status(flags: int):
    return apm.MAVLink_estimator_status_message(0, flags, 0, 0, 0, 0, 0, 0, 0, 0)


def test_the_rules_object_answers_what_the_driver_once_asked_the_autopilots_name_for():
    assert rules_for(apm.MAV_AUTOPILOT_PX4) is PX4Rules and rules_for(apm.MAV_AUTOPILOT_ARDUPILOTMEGA) is ArduPilotRules
    assert PX4Rules.steering is OffboardSteering and ArduPilotRules.steering is RoverSteering
    assert PX4Rules.param_asks == ("RO_YAW_P",) and ArduPilotRules.param_asks == ArduPilotRules.gcs_sysid_params


def test_only_the_autopilots_own_component_is_believed():
    s = Observed(sysid=1, compid=1)
    pos = apm.MAVLink_local_position_ned_message(0, 1.0, 2.0, 0, 0.5, 0, 0)
    assert not believe(s, framed(pos, compid=196), 1.0, ArduPilotRules)  # a lidar driver on the vehicle
    assert not believe(s, framed(pos, sysid=7), 1.0, ArduPilotRules)  # another vehicle
    assert s.position is None and s.heard is None
    assert believe(s, framed(pos), 1.0, ArduPilotRules)
    assert s.position == (1.0, 1.0, 2.0, 0.5, 0.0) and s.heard == 1.0
    gcs_beat = apm.MAVLink_heartbeat_message(apm.MAV_TYPE_GCS, apm.MAV_AUTOPILOT_INVALID, 0, 7, 0, 3)
    believe(s, framed(gcs_beat), 2.0, ArduPilotRules)  # not an autopilot speaking: its mode is not the rover's
    assert s.mode is None


def test_px4s_estimator_status_says_the_position_is_valid_only_under_px4s_rules():
    for rules, believed in ((ArduPilotRules, None), (PX4Rules, EKF_POS_HORIZ_ABS)):
        s = Observed(sysid=1, compid=1)
        believe(s, framed(estimator_status(EKF_POS_HORIZ_ABS)), 1.0, rules)
        assert s.ekf_flags == believed, rules.name


def test_parameters_arrive_in_each_autopilots_encoding():
    bits = struct.unpack("<f", struct.pack("<i", 3))[0]  # PX4: an INT32's bits in the float
    for rules, value in ((PX4Rules, 3.0), (ArduPilotRules, bits)):
        s = Observed(sysid=1, compid=1)
        believe(s, framed(apm.MAVLink_param_value_message(b"NAV_DLL_ACT", bits, apm.MAV_PARAM_TYPE_INT32, 1, 0)),
                1.0, rules)
        assert s.params["NAV_DLL_ACT"] == value and s.param_types["NAV_DLL_ACT"] == apm.MAV_PARAM_TYPE_INT32
