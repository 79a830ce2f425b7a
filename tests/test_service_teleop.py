"""Teleoperation alone: stick and velocity frames in, a teleop setpoint judged by the lease rules, a refused
stream told at most once every two seconds, absurd numbers refused."""

from __future__ import annotations

import math

import pytest

from link.setpoints import VELOCITY, VELOCITY_YAW_RATE
from tests.service_kit import OWNER, STRANGER, Kit, texts
from vehicle.app import MAX_TELEOP_SPEED, MAX_TELEOP_YAW_RATE
from vehicle.services.base import mav
from vehicle.services.teleop import REJECT_NOTICE_GAP, Teleop


def owned() -> tuple[Kit, Teleop]:
    kit = Kit()
    kit.take_control(OWNER)
    return kit, Teleop(kit.out, kit.vehicle, kit.counters, sysid=1)


def stick(x: int, r: int, target: int = 1):
    return mav.MAVLink_manual_control_message(target, x, 0, 500, r, 0)


def velocity(vx: float, vy: float, yaw_rate: float | None, frame: int = mav.MAV_FRAME_BODY_NED,
             mask: int | None = None):
    if mask is None:
        mask = VELOCITY if yaw_rate is None else VELOCITY_YAW_RATE
    return mav.MAVLink_set_position_target_local_ned_message(0, 1, 1, frame, mask, 0, 0, 0, vx, vy, 0, 0, 0, 0, 0,
                                                             0.0 if yaw_rate is None else yaw_rate)


def test_the_owner_s_stick_becomes_a_setpoint_scaled_to_the_limits():
    kit, teleop = owned()
    assert kit.send(teleop, stick(500, -1000)) == []
    sp = kit.vehicle.setpoint
    assert (sp.speed, sp.yaw_rate, sp.sender) == (0.5 * MAX_TELEOP_SPEED, -MAX_TELEOP_YAW_RATE, OWNER)


def test_a_stick_for_another_system_is_a_wrong_target():
    kit, teleop = owned()
    kit.send(teleop, stick(500, 0, target=7))
    assert kit.vehicle.setpoint is None and kit.counters.wrong_target == 1
    kit.send(teleop, stick(500, 0, target=0))  # 0: every system
    assert kit.vehicle.setpoint is not None


def test_a_body_velocity_drives_forward_and_turns_and_is_clamped():
    kit, teleop = owned()
    kit.send(teleop, velocity(1.0, 0.0, 0.5))
    assert (kit.vehicle.setpoint.speed, kit.vehicle.setpoint.yaw_rate) == (1.0, 0.5)
    kit.send(teleop, velocity(99.0, 0.0, None))
    assert (kit.vehicle.setpoint.speed, kit.vehicle.setpoint.yaw_rate) == (MAX_TELEOP_SPEED, 0.0)


def test_a_target_without_velocity_is_not_teleop():
    kit, teleop = owned()
    kit.send(teleop, velocity(1.0, 0.0, None, mask=0b0000_1111_1111_1111))
    assert kit.vehicle.setpoint is None


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_velocity_is_refused_before_it_reaches_the_vehicle(bad):
    kit, teleop = owned()
    with pytest.raises(ValueError, match="finite"):  # the composition answers it with "ignored" and a count
        kit.send(teleop, velocity(bad, 0.0, None, frame=mav.MAV_FRAME_LOCAL_NED))
    assert kit.vehicle.setpoint is None


def test_a_stranger_s_stream_is_refused_and_told_once_every_gap():
    kit, teleop = owned()
    told = []
    for k in range(int(3 * REJECT_NOTICE_GAP / 0.1)):  # 10 Hz for three gaps, the owner heard throughout
        kit.vehicle.heard(OWNER, k * 0.1, k)
        told += texts(kit.send(teleop, stick(1000, 0), sysid=STRANGER, t=k * 0.1))
    assert told == [f"teleop from {STRANGER} refused: sender does not own the vehicle"] * 3
    assert kit.vehicle.setpoint is None
