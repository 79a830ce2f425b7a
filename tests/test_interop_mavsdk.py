"""The real MAVSDK 4 (native library) flies the simulated vehicle over loopback UDP, as a user would."""

from __future__ import annotations

import json
import math
import time

import pytest
from mavsdk import ComponentType, Configuration, Mavsdk
from mavsdk.plugins.action import Action
from mavsdk.plugins.manual_control import ManualControl
from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkDirectResult
from mavsdk.plugins.mission_raw import MissionItem, MissionRaw
from mavsdk.plugins.param import Param
from mavsdk.plugins.telemetry import FlightMode, Telemetry

from link import dialect
from tests.interop import ServedVehicle, wait_until
from vehicle.app import State

# exclusive: run alone after the rest (tests/conftest.py). On two workers the return-to-launch test failed in both
# full runs (MAVSDK never reported RETURN_TO_LAUNCH within 20 s: the plan's first block, a return to the link, ends
# at once where the link is good) and passed in every run alone; the cause under load is not yet found
pytestmark = [pytest.mark.interop, pytest.mark.exclusive]


@pytest.fixture(scope="module")
def flight():
    served = ServedVehicle("tunnel")
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        sdk.add_any_connection(f"udpin://127.0.0.1:{served.gcs_port}")
        system = sdk.first_autopilot(10.0)
        assert system is not None, "MAVSDK did not discover the vehicle"
        yield served, system
    finally:
        sdk.destroy()
        served.close()


def test_health_all_ok_and_position(flight):
    served, system = flight
    tel = Telemetry(system)
    wait_until(tel.health_all_ok, 20, "health_all_ok")
    pos = tel.position()
    assert abs(pos.latitude_deg - 47.3977) < 0.001 and abs(pos.longitude_deg - 8.5456) < 0.001


def test_params_get_set_and_refusal(flight):
    served, system = flight
    par = Param(system)
    assert par.get_param_float("LNK_TIMEOUT") == pytest.approx(3.0)
    par.set_param_float("LNK_TIMEOUT", 4.5)
    assert par.get_param_float("LNK_TIMEOUT") == pytest.approx(4.5)
    assert served.vehicle.params["LNK_TIMEOUT"] == pytest.approx(4.5)
    with pytest.raises(Exception):  # noqa: B017 - MAVSDK raises its own ParamError once the vehicle refuses
        par.set_param_float("LNK_TIMEOUT", 500.0)
    assert served.vehicle.params["LNK_TIMEOUT"] == pytest.approx(4.5)
    par.set_param_float("LNK_TIMEOUT", 3.0)


def test_manual_control_moves_the_vehicle(flight):
    served, system = flight
    Action(system).arm()
    tel = Telemetry(system)
    wait_until(lambda: math.isfinite(tel.position_velocity_ned().position.north_m), 20, "LOCAL_POSITION_NED")
    before = tel.position_velocity_ned().position.north_m
    mc = ManualControl(system)
    for _ in range(10):
        mc.set_manual_control_input(0.0, 0.0, 0.5, 0.0)
        time.sleep(0.05)
    mc.start_position_control()
    for _ in range(50):
        mc.set_manual_control_input(0.8, 0.0, 0.5, 0.0)
        time.sleep(0.05)
    time.sleep(0.4)
    after = tel.position_velocity_ned().position.north_m
    assert after - before > 1.0, f"moved only {after - before:.2f} m north"


def _item(seq: int, command: int, p1: float = 0.0, p3: float = 0.0, p4: float = 0.0) -> MissionItem:
    return MissionItem(seq, 2, command, int(seq == 0), 1, p1, 0.0, p3, p4, 0, 0, 0.0, 0)


def test_mission_raw_upload_and_download_of_a_return_plan(flight):
    served, system = flight
    mr = MissionRaw(system)
    plan = [_item(0, 44002, 30.0, -1.0, -1.0), _item(1, 44003), _item(2, 19, 5.0), _item(3, 44003), _item(4, 20)]
    mr.upload_mission(plan)
    got = mr.download_mission()
    assert [(i.seq, i.command, i.param1) for i in got] == [(i.seq, i.command, i.param1) for i in plan]
    assert len(served.vehicle.book.plan) == 3  # three leases: return to link, loiter, return to launch


def test_return_to_launch_and_hold_read_back_as_flight_modes(flight):
    served, system = flight
    tel, act = Telemetry(system), Action(system)
    act.return_to_launch()
    wait_until(lambda: tel.flight_mode() == FlightMode.RETURN_TO_LAUNCH, 20, "flight mode RETURN_TO_LAUNCH")
    assert served.vehicle.state() == State.RETURNING
    act.hold()
    wait_until(lambda: tel.flight_mode() == FlightMode.HOLD, 20, "flight mode HOLD")
    assert served.vehicle.state() == State.TELEOP  # the operator took a newer lease over the return


def test_mavlink_direct_receives_lease_status(flight):
    served, system = flight
    direct = MavlinkDirect(system)
    assert direct.load_custom_xml(dialect.xml_text()) == MavlinkDirectResult.SUCCESS
    got = []
    direct.subscribe_message("LEASE_STATUS", lambda msg, _ud: got.append(json.loads(msg.fields_json)))
    wait_until(lambda: got, 20, "LEASE_STATUS through MavlinkDirect")
    assert got[-1]["owner_sysid"] == 245  # MAVSDK took the vehicle implicitly (LEASE_AUTOGRANT)
    assert got[-1]["epoch"] == served.vehicle.book.epoch
