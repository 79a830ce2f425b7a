"""A mode asked of the autopilot (``vehicle.companion.mode_request``), told as timelines: seen, sent again, given up,
refused; PX4's rule that a mode it was leaving when asked does not count, and that a refusal of Offboard is asked
again until the tries are spent."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion import px4
from vehicle.companion.mode_request import ModeRequest, Step
from vehicle.companion.observed import Observed
from vehicle.companion.rules import GUIDED, MODE_TRIES, ArduPilotRules, PX4Rules


def ack(result: int):
    return apm.MAVLink_command_ack_message(apm.MAV_CMD_DO_SET_MODE, result)


def asked(mode: int, t: float = 0.0) -> ModeRequest:
    req = ModeRequest()
    req.ask(mode)
    req.sent(t)
    return req


def test_the_mode_seen_in_the_heartbeat_ends_the_request():
    seen = Observed(mode=0, mode_at=0.0)
    req = asked(GUIDED)
    assert req.step(0.5, seen, ArduPilotRules) is Step.NONE
    seen.mode, seen.mode_at = GUIDED, 0.6
    assert req.step(0.6, seen, ArduPilotRules) is Step.DONE and req.wanted is None
    assert req.step(0.7, seen, ArduPilotRules) is Step.NONE


def test_unseen_it_is_sent_again_every_retry_then_given_up_after_its_tries():
    seen = Observed(mode=0)
    req = asked(GUIDED)
    t = 0.0
    for _ in range(MODE_TRIES - 1):
        t += ArduPilotRules.mode_retry
        assert req.step(t, seen, ArduPilotRules) is Step.RESEND
        req.sent(t)
    assert req.step(t + ArduPilotRules.mode_retry / 2, seen, ArduPilotRules) is Step.NONE
    assert req.step(t + ArduPilotRules.mode_retry, seen, ArduPilotRules) is Step.GAVE_UP


def test_px4_a_mode_said_before_the_request_does_not_count():
    """PX4 may still show the owner's Offboard while leaving it: only a heartbeat after the request confirms."""
    seen = Observed(mode=px4.OFFBOARD, mode_at=0.9)
    req = asked(px4.OFFBOARD, t=1.0)
    assert req.step(1.1, seen, PX4Rules) is Step.NONE
    seen.mode_at = 1.2
    assert req.step(1.2, seen, PX4Rules) is Step.DONE
    seen = Observed(mode=GUIDED, mode_at=0.9)  # ArduPilot: the mode is the mode, whenever it was said
    assert asked(GUIDED, t=1.0).step(1.1, seen, ArduPilotRules) is Step.DONE


def test_an_accepted_request_counts_as_said_at_once():
    seen = Observed(mode=0)
    req = asked(GUIDED)
    req.answered(ack(apm.MAV_RESULT_ACCEPTED), 0.1, seen, ArduPilotRules)
    assert (seen.mode, seen.mode_at) == (GUIDED, 0.1)


def test_a_refusal_ends_an_ardupilot_request_at_once_and_a_px4_one_once_its_tries_are_spent():
    seen = Observed(mode=0)
    req = asked(GUIDED)
    req.answered(ack(apm.MAV_RESULT_IN_PROGRESS), 0.1, seen, ArduPilotRules)
    assert req.refused is None
    req.answered(ack(apm.MAV_RESULT_DENIED), 0.1, seen, ArduPilotRules)
    assert req.refused == "the autopilot refused GUIDED (DENIED)"
    assert req.step(0.2, seen, ArduPilotRules) is Step.GAVE_UP
    req = asked(px4.OFFBOARD)
    req.answered(ack(apm.MAV_RESULT_TEMPORARILY_REJECTED), 0.1, seen, PX4Rules)  # its check has not seen the stream
    assert req.refused is None
    req.tries = PX4Rules.mode_tries
    req.answered(ack(apm.MAV_RESULT_TEMPORARILY_REJECTED), 0.1, seen, PX4Rules)
    assert req.refused == "the autopilot refused OFFBOARD (TEMPORARILY_REJECTED)"
