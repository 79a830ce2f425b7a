"""Operator control and leases alone: REQUEST_OPERATOR_CONTROL, LEASE_CLAIM and LEASE_EXPIRE in, COMMAND_ACKs
out, and every lease transition announced on the next tick (LEASE_EVENT, then its STATUSTEXT)."""

from __future__ import annotations

from tests.service_kit import OWNER, STRANGER, Kit, command_long, texts, types
from vehicle.lease import ExpireReason, Holder
from vehicle.services.base import mav
from vehicle.services.commands import CommandServer
from vehicle.services.operator import OperatorControl

REQUEST = mav.MAV_CMD_REQUEST_OPERATOR_CONTROL


def operator(kit: Kit) -> tuple[CommandServer, OperatorControl]:
    op = OperatorControl(kit.out, kit.vehicle, boot_t=0.0)
    return CommandServer(kit.out, kit.counters, [op]), op


def ack(replies: list):
    [a] = [m for m in replies if m.get_type() == "COMMAND_ACK"]
    return a.result, a.result_param2


def test_requesting_control_gives_the_root_and_answers_with_its_epoch():
    kit = Kit()
    commands, _ = operator(kit)
    result, epoch = ack(kit.send(commands, command_long(REQUEST, 1)))
    assert result == mav.MAV_RESULT_ACCEPTED and epoch == kit.vehicle.book.epoch != 0
    assert kit.vehicle.book.owner == OWNER


def test_a_station_cannot_request_control_for_another():
    kit = Kit()
    commands, _ = operator(kit)
    replies = kit.send(commands, command_long(REQUEST, 1, 0, 0, STRANGER))
    assert ack(replies)[0] == mav.MAV_RESULT_DENIED and kit.vehicle.book.owner is None
    assert texts(replies) == ["operator control: a station can only request control for itself"]


def test_a_second_station_is_not_in_control_without_takeover_and_is_told_why():
    kit = Kit()
    commands, _ = operator(kit)
    kit.send(commands, command_long(REQUEST, 1))
    replies = kit.send(commands, command_long(REQUEST, 1), sysid=STRANGER)
    assert ack(replies)[0] == mav.MAV_RESULT_NOT_IN_CONTROL and kit.vehicle.book.owner == OWNER
    assert texts(replies) == [f"control request from {STRANGER} refused: owned by GCS {OWNER}; takeover not allowed"]


def test_release_gives_the_vehicle_back():
    kit = Kit()
    commands, _ = operator(kit)
    kit.send(commands, command_long(REQUEST, 1))
    assert ack(kit.send(commands, command_long(REQUEST, 0)))[0] == mav.MAV_RESULT_ACCEPTED
    assert kit.vehicle.book.owner is None


def test_claim_and_expire_check_their_numbers_before_the_lease_rules():
    kit = Kit()
    commands, _ = operator(kit)
    for msg in (command_long(mav.MAV_CMD_LEASE_CLAIM, 70000, 0), command_long(mav.MAV_CMD_LEASE_EXPIRE, 1, -1)):
        replies = kit.send(commands, msg)
        assert ack(replies)[0] == mav.MAV_RESULT_DENIED
    assert kit.vehicle.book.owner is None  # nothing reached the lease book


def test_each_transition_is_announced_once_on_the_next_tick():
    kit = Kit()
    commands, op = operator(kit)
    kit.send(commands, command_long(REQUEST, 1))
    book = kit.vehicle.book
    op.tick(0.0)
    replies = kit.replies()
    assert types(replies) == ["LEASE_EVENT", "STATUSTEXT"]
    ev = replies[0]
    assert (ev.epoch, ev.expired_index, ev.current_index, ev.reason, ev.holder) == (
        book.epoch, 65535, 0, ExpireReason.NONE, Holder.OPERATOR)
    op.tick(0.02)
    assert kit.replies() == []  # told once
    kit.t = 1.5
    assert ack(kit.send(commands, command_long(mav.MAV_CMD_LEASE_EXPIRE, book.epoch, 0)))[0] == mav.MAV_RESULT_ACCEPTED
    op.tick(1.5)
    ev = kit.replies()[0]
    assert (ev.time_boot_ms, ev.expired_index, ev.current_index, ev.reason, ev.holder) == (
        1500, 0, 1, ExpireReason.OPERATOR_EXPIRE, Holder.RETURN_SERVICE)
