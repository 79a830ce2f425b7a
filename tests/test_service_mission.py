"""The mission protocol alone: an upload item by item, a download, refusals by MISSION_ACK code, the plan's start
and its progress, frames in and frames out, with no endpoint around the service."""

from __future__ import annotations

import math

from gcs.plans import parse_spec
from link.mission import Item, Origin
from tests.service_kit import OWNER, STRANGER, Kit, command_long, texts, types
from vehicle.services.base import mav
from vehicle.services.commands import CommandServer
from vehicle.services.mission import MissionService

PLAN = "rtl:30 | loiter:5"


def service(kit: Kit) -> tuple[MissionService, list]:
    reports: list = []
    missions = MissionService(kit.out, kit.vehicle, Origin(), lambda msgid, t: reports.append((msgid, t)))
    return missions, reports


def item_int(it: Item):
    return mav.MAVLink_mission_item_int_message(1, 1, it.seq, it.frame, it.command, it.current, it.autocontinue,
                                                it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z,
                                                it.mission_type)


def upload(kit: Kit, missions: MissionService, items: list[Item], sysid: int = OWNER) -> list:
    """The station's side of an upload: the count, then each item the vehicle asks for. The last replies."""
    replies = kit.send(missions, mav.MAVLink_mission_count_message(1, 1, len(items), 0), sysid=sysid)
    while replies and replies[-1].get_type() == "MISSION_REQUEST_INT":
        replies = kit.send(missions, item_int(items[replies[-1].seq]), sysid=sysid)
    return replies


def mission_ack(replies: list) -> int:
    [a] = [m for m in replies if m.get_type() == "MISSION_ACK"]
    return a.type


def test_an_upload_requests_every_item_then_schedules_the_return_plan():
    kit = Kit()
    missions, _ = service(kit)
    items = parse_spec(PLAN)
    asked = kit.send(missions, mav.MAVLink_mission_count_message(1, 1, len(items), 0))
    assert types(asked) == ["MISSION_REQUEST_INT"] and asked[0].seq == 0 and asked[0].target_system == OWNER
    replies = upload(kit, missions, items)
    assert mission_ack(replies) == mav.MAV_MISSION_ACCEPTED
    assert texts(replies) == ["return plan: 3 items, 2 leases"]
    assert len(kit.vehicle.plan_items) == 3 and missions.transfer.lists[0] == tuple(items)


def test_a_download_returns_what_was_uploaded():
    kit = Kit()
    missions, _ = service(kit)
    items = parse_spec(PLAN)
    upload(kit, missions, items)
    [count] = kit.send(missions, mav.MAVLink_mission_request_list_message(1, 1, 0), sysid=STRANGER)
    assert count.get_type() == "MISSION_COUNT" and count.count == 3 and count.target_system == STRANGER
    got = [kit.send(missions, mav.MAVLink_mission_request_int_message(1, 1, k, 0), sysid=STRANGER)[0]
           for k in range(3)]
    assert [(m.seq, m.command, m.param1) for m in got] == [(it.seq, it.command, it.param1) for it in items]
    assert mission_ack(kit.send(missions, mav.MAVLink_mission_request_int_message(1, 1, 3, 0))) == \
        mav.MAV_MISSION_INVALID_SEQUENCE


def test_a_stranger_cannot_upload_while_someone_owns_the_vehicle():
    kit = Kit()
    missions, _ = service(kit)
    kit.take_control(OWNER)
    replies = kit.send(missions, mav.MAVLink_mission_count_message(1, 1, 3, 0), sysid=STRANGER)
    assert mission_ack(replies) == mav.MAV_MISSION_DENIED and missions.transfer.upload is None
    assert texts(replies) == [f"mission from {STRANGER} refused: GCS {OWNER} is in control"]


def test_a_float_item_that_cannot_be_a_position_is_refused_by_field():
    kit = Kit()
    missions, _ = service(kit)
    kit.send(missions, mav.MAVLink_mission_count_message(1, 1, 1, 0))
    waypoint = mav.MAVLink_mission_item_message(1, 1, 0, mav.MAV_FRAME_GLOBAL, mav.MAV_CMD_NAV_WAYPOINT, 0, 1,
                                                0, 0, 0, 0, math.inf, 8.5, 0)
    replies = kit.send(missions, waypoint)
    assert mission_ack(replies) == mav.MAV_MISSION_INVALID_PARAM5_X and kit.vehicle.plan_items == ()
    assert "x = inf is not a position" in texts(replies)[0]


def test_only_a_trusted_ack_cancels_an_upload():
    kit = Kit()
    missions, _ = service(kit)
    kit.send(missions, mav.MAVLink_mission_count_message(1, 1, 3, 0))
    cancel = mav.MAVLink_mission_ack_message(1, 1, mav.MAV_MISSION_OPERATION_CANCELLED, 0)
    kit.send(missions, cancel, trusted=False)
    assert missions.transfer.upload is not None
    kit.send(missions, cancel)
    assert missions.transfer.upload is None and missions.transfer.uploads_cancelled == 1


def test_an_upload_that_stalls_times_out_and_keeps_the_previous_plan():
    kit = Kit()
    missions, _ = service(kit)
    upload(kit, missions, parse_spec(PLAN))
    before = kit.vehicle.plan_items
    kit.send(missions, mav.MAVLink_mission_count_message(1, 1, 2, 0))
    for k in range(1, 40):
        missions.tick(k * 0.2)
    replies = kit.replies()
    assert types(replies).count("MISSION_REQUEST_INT") >= 3  # asked again on each time-out
    assert mission_ack(replies) == mav.MAV_MISSION_OPERATION_CANCELLED and kit.vehicle.plan_items == before


def test_setting_the_current_item_moves_the_start_and_reports_it():
    kit = Kit()
    missions, reports = service(kit)
    commands = CommandServer(kit.out, kit.counters, [missions])
    upload(kit, missions, parse_spec(PLAN))
    kit.take_control(OWNER)
    [a] = kit.send(commands, command_long(mav.MAV_CMD_DO_SET_MISSION_CURRENT, 2))
    assert a.result == mav.MAV_RESULT_ACCEPTED and reports == [(mav.MAVLINK_MSG_ID_MISSION_CURRENT, 0.0)]
    assert [[it.seq for it in lease.block.payload] for lease in kit.vehicle.book.scheduled] == [[2]]  # loiter on
    replies = kit.send(missions, mav.MAVLink_mission_set_current_message(1, 1, 7), t=0.5)
    assert texts(replies) == ["set mission current: item 7 does not exist"]
    assert reports[-1] == (mav.MAVLINK_MSG_ID_MISSION_CURRENT, 0.5)  # the current one reported either way
    replies = kit.send(commands, command_long(mav.MAV_CMD_DO_SET_MISSION_CURRENT, 7), t=1.0)
    assert [m.result for m in replies if m.get_type() == "COMMAND_ACK"] == [mav.MAV_RESULT_DENIED]
    assert len(reports) == 2  # refused as a command: nothing to report


def test_items_reached_are_reported_once_on_the_next_tick():
    kit = Kit()
    missions, _ = service(kit)
    kit.vehicle.returns.reached.extend([0, -1, 2])  # (-1: a default block with no item of the plan)
    missions.tick(0.0)
    assert [(m.get_type(), m.seq) for m in kit.replies()] == [("MISSION_ITEM_REACHED", 0), ("MISSION_ITEM_REACHED", 2)]
    missions.tick(0.02)
    assert kit.replies() == []
