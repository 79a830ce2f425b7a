"""Plain pymavlink ground stations: the lease rules seen from outside, over loopback UDP."""

from __future__ import annotations

import time

import pytest
from pymavlink import mavutil

from link import dialect
from tests.interop import ServedVehicle, wait_until

pytestmark = pytest.mark.interop


def _station(port: int, sysid: int):
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=sysid, source_component=190,
                                      dialect="returnlink")
    conn.mav.heartbeat_send(6, 8, 0, 0, 0)
    return conn


def _ack(conn, command: int, timeout: float = 5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        m = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.2)
        if m is not None and m.command == command and m.target_system == conn.source_system:
            return m
    raise AssertionError(f"no COMMAND_ACK for {command}")


@pytest.fixture()
def served():
    sv = ServedVehicle("tunnel")
    yield sv
    sv.close()


def test_second_station_is_refused_and_old_lease_commands_after_takeover(served):
    rl = dialect.load()
    alpha, bravo = _station(served.port, 200), _station(served.port, 201)
    try:
        alpha.mav.command_long_send(1, 1, rl.MAV_CMD_REQUEST_OPERATOR_CONTROL, 0, 1, 1, 10, 0, 0, 0, 0)
        ack = _ack(alpha, rl.MAV_CMD_REQUEST_OPERATOR_CONTROL)
        assert ack.result == rl.MAV_RESULT_ACCEPTED and ack.result_param2 == served.vehicle.book.epoch
        alpha.mav.command_long_send(1, 1, rl.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert _ack(alpha, rl.MAV_CMD_COMPONENT_ARM_DISARM).result == rl.MAV_RESULT_ACCEPTED

        # bravo is not the owner: refused with NOT_IN_CONTROL, and counted
        rejected = served.vehicle.commands_rejected
        bravo.mav.command_long_send(1, 1, rl.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0)
        assert _ack(bravo, rl.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == 10  # MAV_RESULT_NOT_IN_CONTROL
        assert served.vehicle.commands_rejected == rejected + 1

        # alpha allowed takeover: bravo takes the root, a new epoch
        old_epoch = served.vehicle.book.epoch
        bravo.mav.command_long_send(1, 1, rl.MAV_CMD_REQUEST_OPERATOR_CONTROL, 0, 1, 0, 10, 0, 0, 0, 0)
        assert _ack(bravo, rl.MAV_CMD_REQUEST_OPERATOR_CONTROL).result == rl.MAV_RESULT_ACCEPTED
        assert served.vehicle.book.owner == 201 and served.vehicle.book.epoch != old_epoch

        # alpha's stream under its old lease: refused, counted, never executed
        rejected = served.vehicle.commands_rejected
        start = served.server.robot.pose
        for _ in range(20):
            alpha.mav.set_position_target_local_ned_send(0, 1, 1, rl.MAV_FRAME_LOCAL_NED, 0b110111000111,
                                                         0, 0, 0, 1.5, 0, 0, 0, 0, 0, 0, 0)
            time.sleep(0.05)
        alpha.mav.command_long_send(1, 1, rl.MAV_CMD_LEASE_EXPIRE, 0, old_epoch, 0, 0, 0, 0, 0, 0)
        assert _ack(alpha, rl.MAV_CMD_LEASE_EXPIRE).result == 10
        wait_until(lambda: served.vehicle.commands_rejected >= rejected + 21, 20, "21 counted refusals")
        moved = served.server.robot.pose  # the true pose: the robot did not move an inch
        assert abs(moved[0] - start[0]) < 0.02 and served.vehicle.setpoint is None
        assert served.vehicle.control.stale_commands_executed == 0
    finally:
        alpha.close()
        bravo.close()


def test_a_retried_command_is_answered_once_per_message_and_executed_once(served):
    rl = dialect.load()
    gcs = _station(served.port, 255)
    try:
        gcs.mav.command_long_send(1, 1, rl.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert _ack(gcs, rl.MAV_CMD_COMPONENT_ARM_DISARM).result == rl.MAV_RESULT_ACCEPTED
        events = len(served.vehicle.event_log)
        for confirmation in range(3):  # MAVLink retries: same command, confirmation counting up
            gcs.mav.command_long_send(1, 1, rl.MAV_CMD_NAV_RETURN_TO_LAUNCH, confirmation, 0, 0, 0, 0, 0, 0, 0)
            assert _ack(gcs, rl.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == rl.MAV_RESULT_ACCEPTED
        assert [e.reason.name for e in served.vehicle.event_log[events:]].count("OPERATOR_EXPIRE") == 1
        assert served.server.plant.endpoint.counters.command_retries == 2
        gcs.mav.command_long_send(1, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0)
        assert _ack(gcs, 31999).result == rl.MAV_RESULT_UNSUPPORTED
    finally:
        gcs.close()
