"""The heartbeat and standard-modes service alone: identity, armed state, the modes a station can name."""

from __future__ import annotations

from pymavlink.dialects.v20 import development

from tests.service_kit import Kit
from vehicle.modes import AVAILABLE_MODES
from vehicle.services.base import mav
from vehicle.services.heartbeat import Heartbeat


def development_replies(kit: Kit) -> list:
    """The frames produced, parsed with the development dialect (AVAILABLE_MODES and CURRENT_MODE live there)."""
    parser = development.MAVLink(None, 0, 0)
    return [m for frame in kit.out.take() for m in parser.parse_buffer(frame) or []]


def test_a_native_heartbeat_is_the_robots_type_generic_and_standby_until_armed():
    kit = Kit()
    hb = Heartbeat(kit.out.mav, kit.vehicle)
    hb.send(0.0)
    (m,) = kit.replies()
    assert (m.type, m.autopilot) == (kit.driver.mav_type, mav.MAV_AUTOPILOT_GENERIC)
    assert m.system_status == mav.MAV_STATE_STANDBY
    assert m.base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
    assert m.custom_mode == hb.custom_mode()
    kit.vehicle.armed = True
    hb.send(1.0)
    (m,) = kit.replies()
    assert m.system_status == mav.MAV_STATE_ACTIVE and m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED


def test_a_composition_gives_its_own_identity():
    kit = Kit(compid=191)
    Heartbeat(kit.out.mav, kit.vehicle, mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID).send(0.0)
    (m,) = kit.replies()
    assert (m.type, m.autopilot) == (mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID)
    assert (m.get_srcSystem(), m.get_srcComponent()) == (1, 191)


def test_every_mode_is_available_by_index_and_an_index_past_the_end_is_refused():
    kit = Kit()
    hb = Heartbeat(kit.out.mav, kit.vehicle)
    assert hb.available_modes(0)
    every = development_replies(kit)
    assert [m.get_type() for m in every] == ["AVAILABLE_MODES"] * len(AVAILABLE_MODES)
    assert [m.mode_index for m in every] == list(range(1, len(AVAILABLE_MODES) + 1))
    assert {m.custom_mode for m in every} == {m.custom for m in AVAILABLE_MODES}
    assert hb.available_modes(2)
    (one,) = development_replies(kit)
    assert one.custom_mode == AVAILABLE_MODES[1].custom
    assert not hb.available_modes(len(AVAILABLE_MODES) + 1)
    assert kit.replies() == []


def test_the_current_mode_names_the_standard_mode_of_the_state_shown():
    kit = Kit()
    hb = Heartbeat(kit.out.mav, kit.vehicle)
    hb.current_mode(0.0)
    (m,) = development_replies(kit)
    shown = next(x for x in AVAILABLE_MODES if x.custom == hb.custom_mode())
    assert (m.custom_mode, m.standard_mode) == (shown.custom, shown.standard)
