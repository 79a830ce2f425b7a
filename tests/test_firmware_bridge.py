"""The JSON SITL bridge's packet contract, frame rules and servo mapping, tested alone (no firmware needed)."""

from __future__ import annotations

import json
import math
import struct

import pytest

from sim.firmware.bridge import (
    MAGIC,
    SERVO_PACKET,
    FrameRules,
    FrameVerdict,
    ServoFrame,
    ServoMap,
    parse_servo,
    state_reply,
)

pytestmark = pytest.mark.firmware


def packet(count: int, pwm=(1500,) * 16, rate: int = 200, magic: int = MAGIC) -> bytes:
    return SERVO_PACKET.pack(magic, rate, count, *pwm)


def test_a_servo_packet_parses_and_anything_else_is_none():
    f = parse_servo(packet(7, (1100, 0, 1900) + (1500,) * 13))
    assert f == ServoFrame(200, 7, (1100, 0, 1900) + (1500,) * 13)
    assert parse_servo(packet(7, magic=29569)) is None  # the 32-channel layout is not what we answer
    assert parse_servo(packet(7)[:-2]) is None  # truncated
    assert parse_servo(packet(7) + b"\0") is None  # trailing bytes
    assert parse_servo(packet(7, rate=0)) is None  # a zero frame rate would make the step infinite
    assert parse_servo(b"") is None


def test_frame_rules_step_repeat_restart_malformed():
    rules = FrameRules()
    seq = [parse_servo(packet(c)) for c in (0, 1, 1, 2, 5)] + [None, parse_servo(packet(3))]
    got = [rules.judge(f) for f in seq]
    V = FrameVerdict
    assert got == [V.STEP, V.STEP, V.REPEAT, V.STEP, V.STEP, V.MALFORMED, V.RESTART]
    assert rules.counts[FrameVerdict.REPEAT] == 1 and rules.counts[FrameVerdict.MALFORMED] == 1
    # after a restart the new counter is the reference: its next frame steps
    assert rules.judge(parse_servo(packet(4))) is FrameVerdict.STEP


def test_throttle_and_steering_follow_the_sitl_rover_geometry():
    m = ServoMap(max_speed=2.0)
    pwm = [1500] * 16
    pwm[2] = 1750  # throttle +50 %
    speed, rate = m.command(tuple(pwm), speed_now=1.0)
    assert speed == pytest.approx(1.0) and rate == 0.0
    pwm[0] = 2000  # full right lock at 1 m/s: 1.8 m turning circle -> 2 / 1.8 rad/s, to the right (FRD +)
    _, rate = m.command(tuple(pwm), speed_now=1.0)
    assert rate == pytest.approx(2.0 / 1.8)
    _, rate = m.command(tuple(pwm), speed_now=-1.0)  # reversing with the same lock turns the other way
    assert rate == pytest.approx(-2.0 / 1.8)
    _, rate = m.command(tuple(pwm), speed_now=0.0)  # a car does not turn on the spot
    assert rate == 0.0
    pwm[2] = 0  # an output the firmware does not drive is neutral, never full reverse
    assert m.command(tuple(pwm), 0.0)[0] == 0.0
    pwm[2] = 2500  # out of range PWM is clipped to full scale
    assert m.command(tuple(pwm), 0.0)[0] == pytest.approx(2.0)


def test_skid_steering_from_servo_functions_73_and_74():
    m = ServoMap(2.0, {1: 73, 3: 74})
    pwm = [1500] * 16
    pwm[0], pwm[2] = 2000, 1000  # left forward, right backward: turn right on the spot
    speed, rate = m.command(tuple(pwm), 0.0)
    assert speed == pytest.approx(0.0) and rate == pytest.approx(math.radians(140))  # the SITL skid turn rate
    pwm[2] = 2000  # both sides forward: straight on at top speed
    assert m.command(tuple(pwm), 0.0) == pytest.approx((2.0, 0.0))
    with pytest.raises(ValueError, match="neither"):
        ServoMap(2.0, {1: 33, 3: 34})


def test_the_reply_is_newline_framed_json_with_each_vector_right_after_its_key():
    raw = state_reply(1.25, 3.0, -4.0, math.pi / 2, 0.0, 1.0, 1.0, 0.5, 0.2)
    text = raw.decode()
    assert text.startswith("\n") and text.endswith("\n")
    for key in ("gyro", "accel_body", "position", "velocity", "attitude"):
        assert f'"{key}":[' in text  # the firmware finds values by a plain string search
    d = json.loads(text)
    assert d["timestamp"] == 1.25
    assert d["position"] == [3.0, -4.0, 0.0] and d["velocity"] == [0.0, 1.0, 0.0]
    assert d["attitude"][2] == pytest.approx(math.pi / 2)
    assert d["imu"]["gyro"] == [0.0, 0.0, 0.2]
    ax, ay, az = d["imu"]["accel_body"]
    assert ax == 0.5 and ay == pytest.approx(0.2) and az == pytest.approx(-9.80665)  # at rest: -g on z (FRD)


def test_servo_packet_layout_is_the_documented_one():
    assert SERVO_PACKET.format == "<HHI16H" and SERVO_PACKET.size == 40 == struct.calcsize("<HHI16H")
