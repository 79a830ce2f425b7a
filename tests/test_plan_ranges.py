"""Every field of a return-plan item and of a command is range-checked where it enters (link/plan_items.py):
the vehicle's mission protocol answers MAV_MISSION_INVALID_PARAMn naming the field and keeps the old plan, the
RETURN_TO_LINK command is DENIED naming the field, and the ground station refuses the same plans before upload."""

from __future__ import annotations

import math

import pytest

from gcs.plans import PlanError, item, parse_spec, read_wpl
from link.plan_items import (
    LEASE_BOUNDARY,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_RETURN_TO_LINK,
    NAV_WAYPOINT,
    check_item,
)
from tests.harness import Pair
from vehicle.services.base import mav

NAN, INF = math.nan, math.inf


def owned() -> Pair:
    pair = Pair()
    pair.connect()
    p = pair.gs.acquire()
    tr = pair.gs.upload(parse_spec("rtl:30 | loiter:5"))
    pair.until(lambda: p.done and tr.done, 3, "acquire and upload")
    assert tr.ok
    return pair


@pytest.mark.parametrize("params, result, field", [
    ((60, 0, 7, -1), mav.MAV_MISSION_INVALID_PARAM3, "param3 (target)"),
    ((60, 0, 1.5, -1), mav.MAV_MISSION_INVALID_PARAM3, "whole number"),
    ((-5, 0, -1, -1), mav.MAV_MISSION_INVALID_PARAM1, "param1 (max displacement)"),
    ((INF, 0, -1, -1), mav.MAV_MISSION_INVALID_PARAM1, "not a finite number"),
    ((60, 99, -1, -1), mav.MAV_MISSION_INVALID_PARAM2, "param2 (speed)"),
    ((60, 0, -1, 5), mav.MAV_MISSION_INVALID_PARAM4, "param4 (on regain)"),
])
def test_out_of_range_return_item_is_refused_naming_the_field_and_the_old_plan_stays(params, result, field):
    pair = owned()
    plan, items = pair.vehicle.book.plan, pair.vehicle.plan_items
    pair.gs.texts.clear()
    tr = pair.gs.upload([item(0, NAV_RETURN_TO_LINK, *params)])
    pair.until(lambda: tr.done, 3, "MISSION_ACK")
    assert tr.result == result
    assert pair.vehicle.book.plan == plan and pair.vehicle.plan_items == items
    assert any(field in text for _, text in pair.gs.texts), pair.gs.texts


def test_item_fields_beyond_the_params_and_the_command_itself_are_checked():
    assert check_item(NAV_RETURN_TO_LINK, 2, (60, 0, -1, -1), 720, 0, 0).result == mav.MAV_MISSION_INVALID_PARAM5_X
    wp = check_item(NAV_WAYPOINT, 1, (0, 0, 0, 0), round(20000 * 1e4), 0, 0)
    assert wp.result == mav.MAV_MISSION_INVALID_PARAM5_X and "north" in wp.message
    assert check_item(NAV_WAYPOINT, 0, (0, 0, 0, 0), 95 * 10**7, 0, 0).result == mav.MAV_MISSION_INVALID_PARAM5_X
    assert check_item(NAV_WAYPOINT, 0, (0, 0, 0, 0), 0, 0, INF).result == mav.MAV_MISSION_INVALID_PARAM7
    assert check_item(NAV_WAYPOINT, 2, (0, 0, 0, 0), 0, 0, 0).result == mav.MAV_MISSION_UNSUPPORTED_FRAME
    assert check_item(NAV_LOITER_TIME, 2, (NAN, 0, 0, 0), 0, 0, 0).result == mav.MAV_MISSION_INVALID_PARAM1
    assert check_item(NAV_LOITER_TIME, 2, (-1, 0, 0, 0), 0, 0, 0).result == mav.MAV_MISSION_INVALID_PARAM1
    assert check_item(NAV_RETURN_TO_LAUNCH, 2, (0, INF, 0, 0), 0, 0, 0).result == mav.MAV_MISSION_INVALID_PARAM2
    assert check_item(LEASE_BOUNDARY, 2, (0, 0, 0, 0), 0, 0, 0, autocontinue=7).result == mav.MAV_MISSION_INVALID
    assert check_item(31999, 2, (0, 0, 0, 0), 0, 0, 0).result == mav.MAV_MISSION_UNSUPPORTED
    # NaN means "unset" where the field says so: -1 = the parameter, 0 = the parameter's default
    assert check_item(NAV_RETURN_TO_LINK, 2, (NAN, NAN, NAN, NAN), 0, 0, NAN) is None
    assert check_item(NAV_RETURN_TO_LINK, 2, (60, 2, 2, 1), -90, 0, 0) is None


def test_unsupported_command_and_frame_are_refused_with_their_codes():
    pair = owned()
    tr = pair.gs.upload([item(0, 31999)])
    pair.until(lambda: tr.done, 3, "MISSION_ACK")
    assert tr.result == mav.MAV_MISSION_UNSUPPORTED
    tr = pair.gs.upload([item(0, NAV_WAYPOINT, frame=2)])
    pair.until(lambda: tr.done, 3, "MISSION_ACK")
    assert tr.result == mav.MAV_MISSION_UNSUPPORTED_FRAME


@pytest.mark.parametrize("params, needle", [
    ((60, 0, 7, -1), "param3 (target)"),
    ((-5, 0, -1, -1), "param1 (max displacement)"),
    ((60, 99, -1, -1), "param2 (speed)"),
    ((60, 0, -1, 5), "param4 (on regain)"),
    ((NAN, 0, 0.5, -1), "param3 (target)"),
])
def test_return_to_link_command_is_denied_naming_the_field(params, needle):
    pair = owned()
    book = pair.vehicle.book
    pair.gs.texts.clear()
    p = pair.gs.command(mav.MAV_CMD_NAV_RETURN_TO_LINK, *params)
    pair.until(lambda: p.done, 2, "COMMAND_ACK")
    assert p.result == mav.MAV_RESULT_DENIED
    assert pair.vehicle.book.current == book.current and pair.vehicle.returns.service is None
    assert any(needle in text for _, text in pair.gs.texts), pair.gs.texts


@pytest.mark.parametrize("command, params, needle", [
    (mav.MAV_CMD_COMPONENT_ARM_DISARM, (NAN,), "param1 (arm)"),
    (mav.MAV_CMD_COMPONENT_ARM_DISARM, (2,), "param1 (arm)"),
    (mav.MAV_CMD_DO_SET_MODE, (1, INF, 0), "param2 (custom mode)"),
    (mav.MAV_CMD_LEASE_CLAIM, (1, 0.5), "param2 (index)"),
    (mav.MAV_CMD_REQUEST_OPERATOR_CONTROL, (NAN,), "param1 (request)"),
    (mav.MAV_CMD_SET_MESSAGE_INTERVAL, (30, NAN), "param2 (interval)"),
])
def test_command_parameters_are_checked_before_anything_runs(command, params, needle):
    pair = owned()
    armed, book = pair.vehicle.armed, pair.vehicle.book
    pair.gs.texts.clear()
    p = pair.gs.command(command, *params)
    pair.until(lambda: p.done, 2, "COMMAND_ACK")
    assert p.result == mav.MAV_RESULT_DENIED
    assert pair.vehicle.armed == armed and pair.vehicle.book.current == book.current
    assert any(needle in text for _, text in pair.gs.texts), pair.gs.texts


def test_a_valid_return_to_link_command_with_nan_fields_uses_the_parameters():
    pair = owned()
    ran = []
    rtl = pair.vehicle.rtl

    def recording(sender, compid, t, items=()):
        if items:  # (the return to link; the plain RTL it ends in carries none)
            ran.append(items)
        return rtl(sender, compid, t, items)

    pair.vehicle.rtl = recording
    p = pair.gs.command(mav.MAV_CMD_NAV_RETURN_TO_LINK, NAN, NAN, NAN, NAN)
    pair.until(lambda: p.done, 2, "COMMAND_ACK")
    assert p.ok and len(ran) == 1
    it = ran[0][0]
    assert (it.param1, it.param2, it.param3, it.param4) == (0.0, 0.0, -1.0, -1.0)


@pytest.mark.parametrize("spec, needle", [
    ("rtl:60:0:7", "param3 (target)"),
    ("rtl:-1", "param1 (max displacement)"),
    ("rtl:nan:0:0.5", "param3"),
    ("rtl:60:99", "param2 (speed)"),
    ("rtl:60:0:0:5", "param4 (on regain)"),
    ("loiter:-3", "param1 (time)"),
    ("loiter:nan", "NaN"),
    ("wp:1e300:0", "expected rtl"),
    ("wp:20000:0", "north"),
])
def test_ground_station_refuses_the_same_spec_before_upload(spec, needle):
    with pytest.raises(PlanError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        parse_spec(spec)


def test_ground_station_refuses_the_same_wpl_naming_file_and_line():
    text = "QGC WPL 110\n0\t0\t2\t44002\t60\t0\t1\t-1\t0\t0\t0\t1\n1\t0\t2\t44002\t60\t0\t7\t-1\t0\t0\t0\t1\n"
    with pytest.raises(PlanError, match=r"plan.txt:3: RETURN_TO_LINK param3 \(target\): 7 outside"):
        read_wpl(text, "plan.txt")
    assert len(read_wpl(text.rsplit("\n1\t", 1)[0] + "\n", "plan.txt")) == 1


def _sent(pair: Pair, kind: str) -> list:
    msgs = [pair.endpoint.parser.parse_buffer(f) or [] for f in pair.heard]
    return [m for ms in msgs for m in ms if m.get_type() == kind]


def test_a_bad_item_is_refused_as_it_arrives_and_the_rest_is_never_requested():
    pair = owned()
    plan = pair.vehicle.book.plan
    pair.heard.clear()
    tr = pair.gs.upload([item(0, NAV_RETURN_TO_LINK, 60, 0, -1, -1), item(1, NAV_RETURN_TO_LINK, 60, 0, 7, -1),
                         item(2, NAV_LOITER_TIME, 5)])
    pair.until(lambda: tr.done, 3, "MISSION_ACK")
    assert tr.result == mav.MAV_MISSION_INVALID_PARAM3
    assert sorted({m.seq for m in _sent(pair, "MISSION_REQUEST_INT")}) == [0, 1]
    assert pair.vehicle.book.plan == plan and pair.endpoint.missions.upload is None


@pytest.mark.parametrize("x, y, result", [(NAN, 0.0, mav.MAV_MISSION_INVALID_PARAM5_X),
                                          (0.0, INF, mav.MAV_MISSION_INVALID_PARAM6_Y),
                                          (1e30, 0.0, mav.MAV_MISSION_INVALID_PARAM5_X)])
def test_a_float_mission_item_whose_position_is_no_number_is_refused_by_field(x, y, result):
    pair = owned()
    plan = pair.vehicle.book.plan
    enc = mav.MAVLink(None, 255, 190)
    pair.raw.append(mav.MAVLink_mission_count_message(1, 1, 1, 0).pack(enc))
    pair.step(0.1)
    pair.heard.clear()
    pair.raw.append(mav.MAVLink_mission_item_message(1, 1, 0, 0, NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, x, y, 0, 0)
                    .pack(enc))
    pair.step(0.1)
    assert [a.type for a in _sent(pair, "MISSION_ACK")] == [result]
    assert pair.vehicle.book.plan == plan and pair.endpoint.missions.upload is None
