"""What the companion sends the autopilot whatever a return does (``vehicle.companion.upkeep``): the backstop from
the autopilot's ground-station id, withheld when the loop is unhealthy; the streams, and the parameters each
autopilot's rules ask for until one is known."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion.observed import Observed
from vehicle.companion.rules import ArduPilotRules, PX4Rules
from vehicle.companion.upkeep import Upkeep


def test_the_backstop_speaks_as_the_autopilots_ground_station_and_only_for_a_healthy_loop():
    u, s = Upkeep(), Observed(sysid=1, compid=1, params={"MAV_GCS_SYSID": 42.0})
    assert u.keepalive(0.0, False, s, ArduPilotRules) is None
    beat = u.keepalive(0.0, True, s, ArduPilotRules)
    assert beat is not None and beat.type == apm.MAV_TYPE_GCS and u.keepalive_enc.srcSystem == 42
    assert u.keepalive(0.5, True, s, ArduPilotRules) is None and u.keepalives == 1
    assert u.keepalive(1.0, True, s, PX4Rules) is not None and u.keepalive_enc.srcSystem == 255  # PX4: any id


def test_each_autopilot_is_asked_for_the_parameters_its_rules_need_until_one_is_known():
    for rules, names in ((ArduPilotRules, {"MAV_GCS_SYSID", "SYSID_MYGCS"}), (PX4Rules, {"RO_YAW_P"})):
        u, s = Upkeep(), Observed(sysid=1, compid=1)
        out = u.requests(0.0, apm.MAVLink(None, 1, 191), s, rules)
        asked = {m.param_id for m in out if m.get_type() == "PARAM_REQUEST_READ"}
        assert asked == names, rules.name
        assert sum(m.get_type() == "COMMAND_LONG" and m.command == apm.MAV_CMD_SET_MESSAGE_INTERVAL
                   for m in out) == len(rules.streams)
        s.params[next(iter(names))] = 1.0
        out = u.requests(10.0, apm.MAVLink(None, 1, 191), s, rules)
        assert not any(m.get_type() == "PARAM_REQUEST_READ" for m in out)
