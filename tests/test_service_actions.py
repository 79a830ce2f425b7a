"""The vehicle's actions alone: arm, modes and returns, each judged by the lease rules before anything moves."""

from __future__ import annotations

import math

from link.modes import PX4_AUTO, PX4_AUTO_LOITER, PX4_AUTO_RTL, px4_custom_mode
from tests.service_kit import OWNER, STRANGER, Kit, texts
from vehicle.app import State
from vehicle.services.actions import VehicleActions
from vehicle.services.base import Source, mav


def run(svc: VehicleActions, command: int, *params: float, sysid: int = OWNER, t: float = 0.0) -> int:
    p = (*params, *(math.nan,) * (7 - len(params)))
    result, _ = VehicleActions.COMMANDS[command](svc, p, Source(sysid, 190), t)
    return result


def owned() -> tuple[Kit, VehicleActions]:
    kit = Kit()
    kit.take_control(OWNER)
    return kit, VehicleActions(kit.out, kit.vehicle)


def test_the_owner_arms_and_a_stranger_is_refused_with_a_reason():
    kit, svc = owned()
    assert run(svc, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, sysid=STRANGER) != mav.MAV_RESULT_ACCEPTED
    assert not kit.vehicle.armed
    assert any("arm" in text and str(STRANGER) in text for text in texts(kit.replies()))
    assert run(svc, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
    kit.vehicle.tick(0.02)
    assert kit.vehicle.armed


def test_a_mode_this_vehicle_does_not_have_is_denied_and_said():
    kit, svc = owned()
    assert run(svc, mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 99, 0) == mav.MAV_RESULT_DENIED
    assert texts(kit.replies()) == ["mode not supported"]


def test_rtl_as_a_px4_mode_starts_the_return():
    kit, svc = owned()
    run(svc, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    result = run(svc, mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4_AUTO, PX4_AUTO_RTL)
    assert result == mav.MAV_RESULT_ACCEPTED
    kit.vehicle.tick(0.02)
    assert kit.vehicle.state() == State.RETURNING


def test_the_set_mode_message_holds_in_the_px4_encoding():
    kit, svc = owned()
    msg = mav.MAVLink_set_mode_message(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                       px4_custom_mode(PX4_AUTO, PX4_AUTO_LOITER))
    kit.send(svc, msg)
    assert kit.vehicle.holding


def test_return_to_link_runs_one_block_now_for_the_owner_only():
    kit, svc = owned()
    assert run(svc, mav.MAV_CMD_NAV_RETURN_TO_LINK, sysid=STRANGER) != mav.MAV_RESULT_ACCEPTED
    assert kit.vehicle.state() != State.RETURNING
    assert run(svc, mav.MAV_CMD_NAV_RETURN_TO_LINK, 0, 0, 0, 0, 0) == mav.MAV_RESULT_ACCEPTED
    kit.vehicle.tick(0.02)
    assert kit.vehicle.state() == State.RETURNING
