"""Hostile input: garbage, mutated frames, wrong targets and absurd fields never crash the vehicle and never
change its state unless the message is a valid command from whoever is allowed to give it."""

from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.harness import Pair
from vehicle.services.base import mav

FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=32)
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def owned_pair() -> Pair:
    pair = Pair()
    pair.connect()
    p = pair.gs.acquire()
    tr = pair.gs.upload(_plan(pair))
    pair.until(lambda: p.done and tr.done, 3, "acquire and upload")
    return pair


def _plan(pair):
    from gcs.plans import parse_spec

    return parse_spec("rtl:30 | loiter:5")


def snapshot(pair: Pair) -> tuple:
    v = pair.vehicle
    return (v.book.epoch, v.book.owner, v.book.current, v.book.plan, dict(v.params.values), v.plan_items,
            v.armed, v.setpoint)


PAIR = owned_pair()


def _encoder(sysid: int):
    return mav.MAVLink(None, sysid, 190)


def _frame(sysid: int, msg) -> bytes:
    return msg.pack(_encoder(sysid))


@SETTINGS
@given(st.binary(min_size=1, max_size=300))
def test_random_bytes_are_dropped(data):
    before = snapshot(PAIR)
    PAIR.endpoint.receive(data, PAIR.t)
    PAIR.endpoint.receive(b"\xfd" + data, PAIR.t)  # a start-of-frame byte in front of garbage
    assert snapshot(PAIR) == before


def test_a_datagram_that_ends_mid_frame_does_not_swallow_the_next_ones_command():
    """A datagram is whole. One that ends in a start-of-frame byte and a header promising more (garbage, or a frame
    cut short) left the parser waiting for the rest; the owner's next datagram became that rest, failed the CRC and
    its command was lost unanswered (found when the suite's order changed: the stranger property's commands went
    unanswered after another test's garbage)."""
    pair = owned_pair()
    owner = _encoder(255)
    cut = _frame(255, mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0,
                                                       0))[:12]
    for stray in (b"\xfd\xff\x00\x00", cut):
        pair.endpoint.receive(stray, pair.t)
        msg = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0,
                                               mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
        pair.endpoint.receive(msg.pack(owner), pair.t)
        parsed = [m for f in pair.endpoint.tick(pair.t) for m in pair.endpoint.parser.parse_buffer(f)]
        acks = [m for m in parsed if m.get_type() == "COMMAND_ACK" and m.command == mav.MAV_CMD_REQUEST_MESSAGE]
        assert len(acks) == 1 and acks[0].result == mav.MAV_RESULT_ACCEPTED, (stray, [m.get_type() for m in parsed])
        pair.t += 3.1  # past the retry window: the next one is a new command


@SETTINGS
@given(st.integers(min_value=0, max_value=60), st.integers(min_value=1, max_value=255))
def test_a_corrupted_command_frame_changes_nothing(pos, xor):
    rtl = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0)
    frame = bytearray(_frame(255, rtl))
    pos %= len(frame)
    if pos < 10 and pos != 0:
        pos = len(frame) - 1 - (pos % 2)  # corrupt the CRC or payload, not just the header length
    frame[pos] ^= xor
    before = snapshot(PAIR)
    PAIR.endpoint.receive(bytes(frame), PAIR.t)
    assert snapshot(PAIR) == before


@SETTINGS
@given(st.integers(min_value=0, max_value=65535), st.lists(FLOATS, min_size=7, max_size=7),
       st.sampled_from(["long", "int"]))
def test_any_command_from_a_stranger_changes_nothing(command, p, kind):
    if kind == "long":
        msg = mav.MAVLink_command_long_message(1, 1, command, 0, *p)
    else:
        x = int(p[4]) if math.isfinite(p[4]) and abs(p[4]) < 2**31 else 0
        y = int(p[5]) if math.isfinite(p[5]) and abs(p[5]) < 2**31 else 0
        msg = mav.MAVLink_command_int_message(1, 1, 0, command, 0, 0, p[0], p[1], p[2], p[3], x, y, p[6])
    before = snapshot(PAIR)
    PAIR.endpoint.receive(_frame(66, msg), PAIR.t)
    frames = PAIR.endpoint.tick(PAIR.t)
    parsed = [PAIR.endpoint.parser.parse_buffer(f)[0] for f in frames]
    answers = [m for m in parsed if m.get_type() == "COMMAND_ACK" and m.target_system == 66]
    assert len(answers) == 1
    if command not in (mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_SET_MESSAGE_INTERVAL,
                       mav.MAV_CMD_GET_HOME_POSITION, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
        assert answers[0].result != mav.MAV_RESULT_ACCEPTED
    assert snapshot(PAIR)[:7] == before[:7]


@SETTINGS
@given(st.integers(-32768, 32767), st.integers(-32768, 32767), FLOATS, FLOATS, FLOATS,
       st.integers(0, 65535), st.integers(0, 255))
def test_teleop_with_absurd_fields_or_wrong_target_is_refused(x, r, vx, vy, yaw_rate, mask, frame):
    owner, stranger = _encoder(255), _encoder(66)
    before = snapshot(PAIR)
    for enc in (stranger,):
        PAIR.endpoint.receive(mav.MAVLink_manual_control_message(1, x, 0, 500, r, 0).pack(enc), PAIR.t)
        PAIR.endpoint.receive(mav.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, frame, mask, 0, 0, 0, vx, vy, 0, 0, 0, 0, 0, yaw_rate).pack(enc), PAIR.t)
    # the owner, but addressed to another vehicle
    PAIR.endpoint.receive(mav.MAVLink_manual_control_message(7, x, 0, 500, r, 0).pack(owner), PAIR.t)
    PAIR.endpoint.receive(mav.MAVLink_command_long_message(
        7, 1, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0).pack(owner), PAIR.t)
    PAIR.endpoint.tick(PAIR.t)
    assert snapshot(PAIR) == before


@SETTINGS
@given(st.text(min_size=1, max_size=16, alphabet=st.characters(min_codepoint=32, max_codepoint=126)), FLOATS)
def test_param_set_with_any_name_and_value_never_breaks_the_table(name, value):
    enc = _encoder(255)
    before = dict(PAIR.vehicle.params.values)
    PAIR.endpoint.receive(mav.MAVLink_param_set_message(1, 1, name.encode(), value, 9).pack(enc), PAIR.t)
    PAIR.endpoint.tick(PAIR.t)
    after = PAIR.vehicle.params.values
    assert set(after) == set(before)
    for k, v in after.items():
        assert math.isfinite(v)
        if k != name:
            assert v == before[k]
    PAIR.vehicle.params.values.update(before)  # restore for the next example


def test_mission_items_out_of_sequence_or_from_another_station_are_ignored():
    pair = owned_pair()
    enc, other = _encoder(255), _encoder(66)
    old = pair.vehicle.book.plan
    pair.endpoint.receive(mav.MAVLink_mission_count_message(1, 1, 2, 0).pack(enc), pair.t)
    item = mav.MAVLink_mission_item_int_message(1, 1, 1, 2, 19, 0, 1, 5, 0, 0, 0, 0, 0, 0, 0)
    pair.endpoint.receive(item.pack(enc), pair.t)  # seq 1 before seq 0: re-requested, not stored
    pair.endpoint.receive(mav.MAVLink_mission_item_int_message(1, 1, 0, 2, 19, 0, 1, 5, 0, 0, 0, 0, 0, 0, 0)
                          .pack(other), pair.t)  # another station's item: ignored
    pair.endpoint.tick(pair.t)
    assert pair.endpoint.missions.upload is not None and pair.endpoint.missions.upload.items == []
    assert pair.vehicle.book.plan == old


def test_every_supported_command_with_non_finite_parameters_gets_exactly_one_ack():
    """Found by the property test above: SET_MESSAGE_INTERVAL with an infinite id raised and went unanswered."""
    from vehicle.services.native import COMMANDS

    pair = owned_pair()
    stranger, owner = _encoder(66), _encoder(255)
    for command in COMMANDS:
        for bad in (math.inf, -math.inf, math.nan, 1e30):
            for pos in range(7):
                p = [0.0] * 7
                p[pos] = bad
                for enc in (stranger, owner):
                    pair.endpoint.receive(mav.MAVLink_command_long_message(1, 1, command, 0, *p).pack(enc), pair.t)
                    frames = pair.endpoint.tick(pair.t)
                    acks = [m for f in frames for m in pair.endpoint.parser.parse_buffer(f)
                            if m.get_type() == "COMMAND_ACK"]
                    assert len(acks) == 1, (command, bad, pos)
                    pair.t += 3.1  # past the retry window: each is a new command
