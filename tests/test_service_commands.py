"""The command microservice alone: COMMAND_LONG / COMMAND_INT frames in, exactly one COMMAND_ACK out each."""

from __future__ import annotations

import math

import pytest

from tests.service_kit import OWNER, Kit, command_long, texts, types
from vehicle.lease import Check, RejectReason, Verdict
from vehicle.services.base import Service, Source, command, mav
from vehicle.services.commands import RETRY_WINDOW, CommandServer, answer


class Arming(Service):
    """A service with one command, counting what it carries out."""

    def __init__(self) -> None:
        self.runs: list[tuple] = []
        self.fail: Exception | None = None

    @command(mav.MAV_CMD_COMPONENT_ARM_DISARM)
    def _arm(self, p: tuple, src: Source, t: float):
        if self.fail is not None:
            raise self.fail
        self.runs.append((p[0], src.sysid, t))
        return mav.MAV_RESULT_ACCEPTED, 7


def server(kit: Kit, **options) -> tuple[CommandServer, Arming]:
    arming = Arming()
    return CommandServer(kit.out, kit.counters, [arming], **options), arming


def acks(replies: list) -> list[tuple[int, int, int]]:
    return [(m.command, m.result, m.result_param2) for m in replies if m.get_type() == "COMMAND_ACK"]


def test_a_command_runs_its_handler_and_is_answered_once_to_its_sender():
    kit = Kit()
    commands, arming = server(kit)
    replies = kit.send(commands, command_long(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1))
    assert acks(replies) == [(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED, 7)]
    assert (replies[0].target_system, replies[0].target_component) == (OWNER, 190)
    assert arming.runs == [(1.0, OWNER, 0.0)] and kit.counters.commands == 1


def test_command_int_carries_the_same_command():
    kit = Kit()
    commands, arming = server(kit)
    msg = mav.MAVLink_command_int_message(1, 1, 0, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 1, 0, 0, 0, 0, 0, 0)
    assert acks(kit.send(commands, msg)) == [(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED, 7)]
    assert len(arming.runs) == 1


def test_a_retry_within_the_window_gets_the_first_answer_and_never_runs_again():
    kit = Kit()
    commands, arming = server(kit)
    msg = command_long(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    first = acks(kit.send(commands, msg, t=10.0))
    arming.fail = RuntimeError("must not run again")
    assert acks(kit.send(commands, msg, t=10.0 + RETRY_WINDOW - 0.1)) == first
    assert len(arming.runs) == 1 and kit.counters.command_retries == 1
    arming.fail = None
    kit.send(commands, msg, t=10.0 + RETRY_WINDOW + 0.2)  # past the window: a new command
    assert len(arming.runs) == 2


def test_an_unknown_command_is_unsupported_and_counted():
    kit = Kit()
    commands, _ = server(kit)
    assert acks(kit.send(commands, command_long(mav.MAV_CMD_DO_SET_SERVO, 1, 1500))) == [
        (mav.MAV_CMD_DO_SET_SERVO, mav.MAV_RESULT_UNSUPPORTED, 0)]
    assert kit.counters.unsupported == 1


def test_with_an_unknown_hook_a_command_nobody_declares_goes_there_unanswered():
    kit = Kit()
    passed = []
    commands, _ = server(kit, unknown=lambda m, src, t: passed.append((m.command, src.sysid)))
    assert kit.send(commands, command_long(mav.MAV_CMD_DO_SET_SERVO, 1, 1500)) == []
    assert passed == [(mav.MAV_CMD_DO_SET_SERVO, OWNER)] and kit.counters.unsupported == 0
    assert acks(kit.send(commands, command_long(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)))  # its own still answered


@pytest.mark.parametrize("bad", [2.0, math.nan, math.inf, 0.5])
def test_a_parameter_out_of_range_is_denied_by_name_and_never_run(bad):
    kit = Kit()
    commands, arming = server(kit)
    replies = kit.send(commands, command_long(mav.MAV_CMD_COMPONENT_ARM_DISARM, bad))
    assert acks(replies) == [(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_DENIED, 0)]
    assert any("param1 (arm)" in text for text in texts(replies)) and arming.runs == []


def test_a_handler_that_raises_is_answered_failed_counted_and_reported():
    kit = Kit()
    commands, arming = server(kit)
    arming.fail = RuntimeError("broke")
    replies = kit.send(commands, command_long(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1))
    assert acks(replies) == [(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_FAILED, 0)]
    assert types(replies).count("COMMAND_ACK") == 1 and kit.counters.handler_faults == 1
    assert any("RuntimeError: broke" in text for text in texts(replies))


def test_a_command_declared_twice_is_a_composition_error():
    kit = Kit()
    with pytest.raises(ValueError, match="COMPONENT_ARM_DISARM"):
        CommandServer(kit.out, kit.counters, [Arming(), Arming()])


def test_a_lease_verdict_answers_by_one_table():
    kit = Kit()
    assert answer(kit.out, Check(Verdict.EXECUTE, None), "arm", OWNER) == (mav.MAV_RESULT_ACCEPTED, 0)
    assert answer(kit.out, Check(Verdict.QUEUE, None), "arm", OWNER) == (mav.MAV_RESULT_IN_PROGRESS, 0)
    assert kit.replies() == []
    refused = Check(Verdict.REJECT, None, RejectReason.NOT_IN_CONTROL, "GCS 9 is in control")
    assert answer(kit.out, refused, "arm", 66) == (mav.MAV_RESULT_NOT_IN_CONTROL, 0)
    assert texts(kit.replies()) == ["arm from 66 refused: GCS 9 is in control"]
    expired = Check(Verdict.REJECT, None, RejectReason.EXPIRED)
    assert answer(kit.out, expired, "arm", 66) == (mav.MAV_RESULT_DENIED, 0)
