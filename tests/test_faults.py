"""A fault inside the vehicle's software is contained: the return service raising ends its block and the vehicle
holds still and says so; a message handler raising is counted and reported. Neither ever ends the process."""

from __future__ import annotations

from tests.harness import Pair
from vehicle import contingency
from vehicle.app import State
from vehicle.lease import ExpireReason, Holder
from vehicle.services.base import mav


def returning(pair: Pair) -> Pair:
    pair.take_control("rtl:30 | loiter:5")
    pair.gs.drive_velocity(1.0, 0.0)
    pair.step(6.0)
    pair.gs.stop()
    pair.step(0.5)
    return pair


def test_a_fault_in_the_service_step_ends_the_block_holds_and_reports(monkeypatch):
    pair = returning(Pair())

    def broken(*args, **kwargs):
        raise RuntimeError("injected fault")

    monkeypatch.setattr(contingency, "step_block", broken)
    r = pair.gs.rtl()
    pair.until(lambda: r.done, 2, "RTL ACK")
    pair.step(1.0)
    v = pair.vehicle
    # both blocks of the chain started and faulted; the chain is over: a fresh, unclaimed operator lease
    assert v.returns.faults == 2
    assert v.book.current.holder is Holder.OPERATOR and not v.book.current.claimed
    assert v.state() == State.AWAITING_CLAIM
    reasons = [ev.reason for ev in v.event_log]
    assert reasons.count(ExpireReason.STUCK) == 2
    pair.step(1.0)  # still running, and still: nothing drives it
    assert v.control.command_out == (0.0, 0.0)
    assert any("return service fault" in text and "injected fault" in text for _, text in pair.gs.texts)


def test_a_fault_when_the_service_starts_is_contained_the_same_way(monkeypatch):
    pair = returning(Pair())
    monkeypatch.setattr(contingency, "start_block", lambda *a, **k: 1 / 0)
    e = pair.gs.expire()
    pair.until(lambda: e.done, 2, "expire ACK")
    pair.step(1.0)
    assert pair.vehicle.returns.faults == 2 and pair.vehicle.state() == State.AWAITING_CLAIM
    assert pair.vehicle.control.command_out == (0.0, 0.0)
    assert any("ZeroDivisionError" in text for _, text in pair.gs.texts)


def test_a_fault_in_a_message_handler_is_counted_reported_and_not_fatal(monkeypatch):
    from vehicle.services.params import ParamServer

    pair = Pair()
    pair.connect()

    def broken(self, index):
        raise RuntimeError("handler broke")

    monkeypatch.setattr(ParamServer, "value", broken)  # what the PARAM_REQUEST_LIST handler sends each value with
    pair.gs.param_request_all()
    pair.step(0.2)
    assert pair.endpoint.counters.handler_faults == 1
    assert any("fault handling PARAM_REQUEST_LIST" in text for _, text in pair.gs.texts)
    p = pair.gs.acquire()  # and the vehicle carries on answering
    pair.until(lambda: p.done, 2, "ACK")
    assert p.ok


def test_a_fault_in_a_command_handler_is_answered_failed_once(monkeypatch):
    from vehicle.services.telemetry import Telemetry

    pair = Pair()
    pair.connect()

    def broken(self, msgid, t):
        raise RuntimeError("command broke")

    monkeypatch.setattr(Telemetry, "emit", broken)  # what the GET_HOME_POSITION handler sends HOME_POSITION with
    p = pair.gs.command(mav.MAV_CMD_GET_HOME_POSITION)
    pair.until(lambda: p.done, 2, "COMMAND_ACK")
    assert p.result == mav.MAV_RESULT_FAILED
    assert pair.endpoint.counters.handler_faults == 1
    pair.step(1.0)
    assert [r for _, c, r in pair.gs.acks if c == mav.MAV_CMD_GET_HOME_POSITION] == [mav.MAV_RESULT_FAILED]
