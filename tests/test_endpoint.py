"""The MAVLink endpoint against the ground-station library, in simulated time."""

from __future__ import annotations

import math

import pytest

from gcs.plans import parse_spec
from tests.harness import Pair
from vehicle.app import State
from vehicle.modes import decode_mode
from vehicle.params import SPECS
from vehicle.services.base import mav


def acquired(pair: Pair) -> Pair:
    pair.connect()
    p = pair.gs.acquire()
    pair.until(lambda: p.done, 2, "ACK")
    assert p.ok and p.param2 == pair.vehicle.book.epoch
    pair.until(lambda: pair.gs.vehicle.status.epoch == p.param2, 2, "the new epoch")
    a = pair.gs.arm()
    pair.until(lambda: a.done, 2, "arm ACK")
    return pair


def test_heartbeat_and_telemetry_set():
    pair = Pair()
    pair.step(2.0)
    seen = {pair.endpoint.parser.parse_buffer(f)[0].get_type() for f in pair.heard}
    assert {"HEARTBEAT", "SYS_STATUS", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE", "GPS_RAW_INT",
            "EXTENDED_SYS_STATE", "HOME_POSITION", "MISSION_CURRENT", "CONTROL_STATUS", "LEASE_STATUS"} <= seen
    hb = pair.gs.vehicle
    assert hb.mav_type == mav.MAV_TYPE_GROUND_ROVER and not hb.armed


def test_set_message_interval_changes_the_rate():
    pair = Pair()
    p = pair.gs.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, 50_000)
    pair.step(0.1)
    assert p.ok
    count = len(pair.heard)
    pair.heard.clear()
    pair.step(1.0)
    n = sum(1 for f in pair.heard if pair.endpoint.parser.parse_buffer(f)[0].get_type() == "ATTITUDE")
    assert 18 <= n <= 22 and count > 0
    q = pair.gs.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, 9999, 50_000)  # no such telemetry
    pair.step(0.1)
    assert q.result == mav.MAV_RESULT_DENIED


def test_request_message_autopilot_version_capabilities():
    pair = Pair()
    got = []
    pair.gs.listeners.append(lambda m, t: got.append(m) if m.get_type() == "AUTOPILOT_VERSION" else None)
    p = pair.gs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    pair.step(0.1)
    assert p.ok and got
    caps = got[0].capabilities
    for bit in ("MISSION_INT", "COMMAND_INT", "MAVLINK2", "COMPONENT_ACCEPTS_GCS_CONTROL"):
        assert caps & getattr(mav, f"MAV_PROTOCOL_CAPABILITY_{bit}")


def test_unknown_command_is_unsupported_and_changes_nothing():
    pair = acquired(Pair())
    before = pair.vehicle.book
    p = pair.gs.command(31999, 1, 2, 3)
    pair.step(0.1)
    assert p.result == mav.MAV_RESULT_UNSUPPORTED
    assert pair.vehicle.book.epoch == before.epoch and pair.vehicle.book.current == before.current


def test_lease_claim_expire_and_stale_guard():
    pair = acquired(Pair())
    gs = pair.gs
    e = gs.expire()
    pair.until(lambda: e.done, 2, "ACK")
    assert e.ok and pair.vehicle.state() == State.RETURNING
    gs.drive_velocity(1.0, 0.0)  # the operator's old lease is expired: refused, never executed
    pair.step(0.5)
    assert pair.vehicle.setpoint is None and pair.vehicle.commands_rejected >= 3
    assert any("refused" in text for _, text in gs.texts)
    gs.stop_streaming()
    c = gs.claim(0)  # a newer lease over the running return (NEWER_LEASE)
    pair.until(lambda: c.done, 2, "ACK")
    assert c.ok and c.param2 == pair.vehicle.book.current.index
    assert pair.vehicle.event_log[-1].reason.name == "NEWER_LEASE"
    bad = gs.command(mav.MAV_CMD_LEASE_CLAIM, pair.vehicle.book.epoch + 1, 0)  # wrong epoch
    pair.step(0.1)
    assert bad.result == mav.MAV_RESULT_DENIED


def test_other_station_is_not_in_control_and_may_not_upload():
    pair = Pair(stations=(255, 200))
    acquired(pair)
    other = pair.stations[200]
    p = other.rtl()
    tr = other.upload(parse_spec("loiter:5"))
    pair.step(0.5)
    assert p.result == mav.MAV_RESULT_NOT_IN_CONTROL
    assert tr.done and tr.result == mav.MAV_MISSION_DENIED
    assert pair.vehicle.plan_items == ()


def test_mission_upload_download_and_refusal_keeps_the_old_plan():
    pair = acquired(Pair())
    gs = pair.gs
    items = parse_spec("rtl:40 | loiter:10 | launch")
    tr = gs.upload(items)
    pair.until(lambda: tr.done, 3, "MISSION_ACK")
    assert tr.ok and len(pair.vehicle.book.plan) == 3 and pair.vehicle.book.scheduled
    down = gs.download()
    pair.until(lambda: down.done, 3, "download")
    assert [(i.command, i.param1) for i in down.items] == [(i.command, i.param1) for i in items]
    bad = parse_spec("rtl:40") + [parse_spec("rtl")[0].__class__(1, 2, 22, 0, 1, 0, 0, 0, 0, 0, 0, 0.0, 0)]
    tr = gs.upload(bad)  # MAV_CMD_NAV_TAKEOFF has no place in a return plan
    pair.until(lambda: tr.done, 3, "MISSION_ACK")
    assert tr.result == mav.MAV_MISSION_UNSUPPORTED and len(pair.vehicle.book.plan) == 3


def test_truncated_upload_times_out_and_keeps_the_old_plan():
    pair = acquired(Pair())
    gs = pair.gs
    tr = gs.upload(parse_spec("rtl:30 | loiter:5"))
    pair.until(lambda: tr.done, 3, "upload")
    old = pair.vehicle.book.plan
    gs.mav.mission_count_send(1, 1, 4, 0)  # announce 4 items, then go silent
    gs.transfer = None
    acks = []
    gs.listeners.append(lambda m, t: acks.append(m.type) if m.get_type() == "MISSION_ACK" else None)
    pair.step(4.0)
    assert acks == [mav.MAV_MISSION_OPERATION_CANCELLED]
    assert pair.vehicle.book.plan == old and pair.endpoint.missions.uploads_cancelled == 1


def test_fence_and_rally_lists_are_stored_but_not_the_return_plan():
    pair = acquired(Pair())
    items = parse_spec("wp:10:0 wp:0:10")
    tr = pair.gs.upload(items, mission_type=1)
    pair.until(lambda: tr.done, 3, "upload")
    assert tr.ok and pair.vehicle.plan_items == ()
    down = pair.gs.download(mission_type=1)
    pair.until(lambda: down.done, 3, "download")
    assert [i.x for i in down.items] == [i.x for i in items]


def test_params_real32_range_refusal_and_sixteen_char_names():
    pair = Pair()
    gs = pair.gs
    gs.param_request_all()
    pair.step(0.1)
    assert len(gs.vehicle.params) == len(SPECS) and gs.vehicle.param_count == len(SPECS)
    gs.param_set("LNK_TIMEOUT", 999.0)
    pair.step(0.1)
    assert gs.vehicle.params["LNK_TIMEOUT"] == 3.0 and pair.vehicle.params["LNK_TIMEOUT"] == 3.0
    assert any("outside" in text for _, text in gs.texts)
    gs.param_set("LEASE_STALE_TAKE", 0.0)  # 16 characters: no terminating NUL on the wire
    pair.step(0.1)
    assert pair.vehicle.params["LEASE_STALE_TAKE"] == 0.0 and pair.vehicle.book.config.stale_take is False
    gs.param_set("NO_SUCH_PARAM_XX", 1.0)
    pair.step(0.1)
    assert "NO_SUCH_PARAM_XX" not in gs.vehicle.params


def test_rtl_mode_both_encodings_and_hold():
    assert decode_mode(1, 4, 5) == "RTL" and decode_mode(1, 11, 0) == "RTL" and decode_mode(1, 12, 0) == "RTL"
    assert decode_mode(1, 4, 3) == "HOLD" and decode_mode(1, 4, 0) == "HOLD"
    assert decode_mode(1, 3, 0) == "MANUAL" and decode_mode(1, 0, 0) == "MANUAL" and decode_mode(0, 4, 5) is None
    pair = acquired(Pair())
    pair.gs.drive_velocity(1.0, 0.0)
    pair.step(4.0)
    pair.gs.stop_streaming()
    p = pair.gs.command(mav.MAV_CMD_DO_SET_MODE, 1, 11)  # ArduPilot Rover RTL, as MAVProxy sends it
    pair.step(0.2)
    assert p.ok and pair.vehicle.state() == State.RETURNING
    pair.step(1.0)
    assert pair.gs.vehicle.custom_mode == (4 << 16) | (5 << 24)  # PX4 AUTO_RTL in the heartbeat
    h = pair.gs.hold()
    pair.step(0.2)
    assert h.ok and pair.vehicle.state() == State.TELEOP and pair.vehicle.holding


def test_teleop_moves_and_dies_with_its_lease():
    pair = acquired(Pair())
    x0 = pair.driver.pose[0]
    pair.gs.drive_velocity(1.0, 0.0)
    pair.step(3.0)
    assert pair.driver.pose[0] - x0 > 1.5
    pair.gs.stop_streaming()  # the dead-man: no fresh setpoint, the robot stops
    pair.step(2.0)
    assert abs(pair.vehicle.control.command_out[0]) < 1e-9
    pair.gs.drive_manual(0.5, 0.0)
    pair.step(1.0)
    assert pair.vehicle.control.command_out[0] == pytest.approx(1.0)
    assert math.isfinite(pair.vehicle.estimator.pose.x)


def test_mission_current_set_current_and_item_reached():
    pair = acquired(Pair())
    gs = pair.gs
    tr = gs.upload(parse_spec("loiter:1 | loiter:1 | loiter:2"))
    pair.until(lambda: tr.done, 3, "upload")
    assert tr.ok
    bad = gs.command(mav.MAV_CMD_DO_SET_MISSION_CURRENT, 9)
    pair.step(0.1)
    assert bad.result == mav.MAV_RESULT_DENIED
    p = gs.command(mav.MAV_CMD_DO_SET_MISSION_CURRENT, 2)  # start the plan at its second block
    pair.step(0.1)
    assert p.ok and len(pair.vehicle.book.scheduled) == 2
    reached, current = [], []
    gs.listeners.append(lambda m, t: reached.append(m.seq) if m.get_type() == "MISSION_ITEM_REACHED" else None)
    gs.listeners.append(lambda m, t: current.append((m.seq, m.mission_state))
                        if m.get_type() == "MISSION_CURRENT" else None)
    e = gs.expire()
    pair.until(lambda: e.done, 2, "ACK")
    pair.step(4.0)
    assert reached == [2, 4]
    assert (2, mav.MISSION_STATE_ACTIVE) in current and (4, mav.MISSION_STATE_ACTIVE) in current
    assert pair.vehicle.state() == State.AWAITING_CLAIM


def test_parameters_are_saved_back_to_the_parm_file(tmp_path):
    from vehicle.params import load_defaults

    parm = tmp_path / "vehicle.parm"
    pair = Pair()
    pair.endpoint.param_file = parm
    pair.gs.param_set("RTL_MAX_DISP", 75.0)
    pair.step(0.1)
    assert load_defaults(parm)["RTL_MAX_DISP"] == 75.0
    pair.gs.param_set("RTL_MAX_DISP", -1.0)  # refused: the file keeps the good value
    pair.step(0.1)
    assert load_defaults(parm)["RTL_MAX_DISP"] == 75.0


def test_stale_guards_catch_a_setpoint_that_slipped_past_the_lease_check(monkeypatch):
    """Both last lines of defence, tested by breaking the first: the actuator guard in the vehicle and the
    simulator's independent audit each count (and the guard stops) a setpoint from an expired lease."""
    from types import SimpleNamespace

    from sim.runner import Run
    from sim.scenario import load
    from vehicle.app import Setpoint
    from vehicle.lease import Check, LeaseBook, LeaseId, Verdict

    pair = acquired(Pair())
    v = pair.vehicle
    old = v.book.current_id
    e = pair.gs.expire()
    pair.until(lambda: e.done, 2, "ACK")
    c = pair.gs.claim(0)  # a newer operator lease: [E,0] is now stale
    pair.until(lambda: c.done, 2, "ACK")
    monkeypatch.setattr(LeaseBook, "check", lambda self, sender, claim=None: Check(Verdict.EXECUTE, claim))
    v.setpoint = Setpoint(1.0, 0.0, old, pair.t + 5, 255)
    pair.step(0.1)
    assert v.control.stale_commands_executed == 1 and v.setpoint is None and v.control.command_out == (0.0, 0.0)

    run = Run(load("open"))
    run.announced = (old.epoch, old.index + 5)
    fake = SimpleNamespace(setpoint=Setpoint(1.0, 0.0, LeaseId(old.epoch, (old.index,)), 9.0, 255),  # a Status
                           command_out=(1.0, 0.0), book=SimpleNamespace(owner=255))
    run._audit(fake)
    assert run.audit_stale == 1
    fake.setpoint = Setpoint(1.0, 0.0, LeaseId(old.epoch, (old.index + 5,)), 9.0, 200)  # right lease, wrong sender
    run._audit(fake)
    assert run.audit_stale == 2


def test_a_cleared_setpoint_is_judged_again_once_its_lease_is_gone():
    """The teleop guards judge a setpoint again every tick it drives (never a cached verdict): a lease that ends
    makes a new book, and the same setpoint must stop at the next tick."""
    from vehicle.app import DT

    pair = acquired(Pair())
    v = pair.vehicle
    pair.gs.drive_velocity(1.0, 0.0)
    pair.step(1.0)
    sp = v.setpoint
    assert sp is not None and sp.speed > 0.0 and v.control.command_out == (sp.speed, sp.yaw_rate)
    t1, t2 = round(pair.t + DT, 9), round(pair.t + 2 * DT, 9)
    assert t2 <= sp.until  # alive for both ticks below: only its lease can stop it
    v.tick(t1)  # the same book and setpoint: judged again, the same answer
    assert v.setpoint is sp and v.control.command_out == (sp.speed, sp.yaw_rate)
    assert v.claim(v.book.owner, v.book.epoch, v.book.next_index, t1).executes  # a newer lease: sp's is stale
    assert v.setpoint is sp
    v.tick(t2)
    assert v.setpoint is None and v.control.command_out == (0.0, 0.0) and v.control.stale_commands_executed == 0


def test_a_lease_change_is_reported_in_the_tick_it_happens():
    """LEASE_STATUS and CONTROL_STATUS go out in the tick the book changes (an acquire), not at their next slot,
    even between their periodic slots, and the quiet ticks after it send neither."""
    pair = Pair()
    pair.connect()
    pair.step(0.1)  # off the 2 Hz and 1 Hz slots
    p = pair.gs.acquire()
    frames: list[list[str]] = []
    while not p.done:
        pair.heard.clear()
        pair.step()
        frames.append([pair.endpoint.parser.parse_buffer(f)[0].get_type() for f in pair.heard])
    acked = frames[-1]
    assert "COMMAND_ACK" in acked and "LEASE_STATUS" in acked and "CONTROL_STATUS" in acked
    assert pair.gs.vehicle.status.epoch == pair.vehicle.book.epoch
    pair.heard.clear()
    pair.step(0.06)  # three quiet ticks: nothing changed, no slot due
    quiet = [pair.endpoint.parser.parse_buffer(f)[0].get_type() for f in pair.heard]
    assert "LEASE_STATUS" not in quiet and "CONTROL_STATUS" not in quiet


def test_every_handler_is_routed_and_targets_are_checked_from_the_table():
    """``Endpoint.handle`` takes each type's handler and target fields from its routes, not from probing the
    message: every message type a composed service declares must reach that service, and the table must judge
    targets as the fields say."""
    from vehicle.services.native import HANDLED

    pair = Pair()
    declared = {kind: s for s in pair.endpoint.services for kind in type(s).MESSAGES}
    assert set(declared) == HANDLED
    assert all(pair.endpoint.owner(kind) is s for kind, s in declared.items())
    assert pair.endpoint.owner("HEARTBEAT") is None and pair.endpoint.owner("ATTITUDE") is None
    pair.connect()
    enc = mav.MAVLink(None, 255, 190)
    c = pair.endpoint.counters

    def velocity(ts: int, tc: int) -> bytes:
        return mav.MAVLink_set_position_target_local_ned_message(
            0, ts, tc, mav.MAV_FRAME_BODY_NED, 0b0000_1101_1100_0111, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0, 0).pack(enc)

    for ts, tc, wrong in ((1, 1, 0), (0, 0, 0), (1, 0, 0), (1, 5, 1), (7, 1, 1), (0, 5, 1)):
        before = (c.wrong_target, c.frames)
        pair.endpoint.receive(velocity(ts, tc), pair.t)
        assert (c.wrong_target - before[0], c.frames - before[1]) == (wrong, 1), (ts, tc)
    before = c.wrong_target
    pair.endpoint.receive(mav.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(enc), pair.t)  # no target fields
    pair.endpoint.receive(mav.MAVLink_manual_control_message(1, 0, 0, 500, 0, 0).pack(enc), pair.t)
    assert c.wrong_target == before
    pair.endpoint.receive(mav.MAVLink_manual_control_message(7, 0, 0, 500, 0, 0).pack(enc), pair.t)
    assert c.wrong_target == before + 1  # its own ``target`` field, checked by its handler
