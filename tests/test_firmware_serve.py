"""`sim serve --vehicle ardurover`: the firmware in real time (here 20x) behind the radio proxy, answering an
ordinary pymavlink ground station on loopback, alone or with returnlink companion on its telemetry port."""

from __future__ import annotations

import io
import socket
import threading
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from gcs.station import GroundStation, mav
from sim.scenario import load
from sim.serve import Server
from tests.firmware_helpers import firmware_or_skip
from vehicle.companion.router import COMPANION_COMPID

pytestmark = pytest.mark.firmware


def test_a_plain_ground_station_hears_and_commands_the_served_firmware():
    firmware = firmware_or_skip()
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(0.2)
    server = Server(load("tunnel"), "ardurover", 1, port=0, peers=(gcs.getsockname(),), perfect_link=True,
                    policy="ardupilot-hold", firmware=firmware, speedup=20.0)
    thread = threading.Thread(target=server.serve, kwargs={"speedup": 20.0, "duration": 40.0, "out": io.StringIO()},
                              daemon=True)
    thread.start()
    mav = apm.MAVLink(None, srcSystem=255, srcComponent=190)
    seen: dict[str, object] = {}
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline and "ack" not in seen:
            try:
                data, _ = gcs.recvfrom(65535)
            except TimeoutError:
                continue
            for m in mav.parse_buffer(data) or ():
                if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1:
                    seen["heartbeat"] = m
                    gcs.sendto(apm.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(mav), server.address)
                    gcs.sendto(apm.MAVLink_command_long_message(
                        1, 1, apm.MAV_CMD_REQUEST_MESSAGE, 0, apm.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0,
                        0).pack(mav), server.address)
                elif m.get_type() == "COMMAND_ACK" and m.command == apm.MAV_CMD_REQUEST_MESSAGE:
                    seen["ack"] = m
    finally:
        thread.join(90)
        gcs.close()
        server.close()
    assert seen["heartbeat"].autopilot == apm.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert seen["ack"].result == apm.MAV_RESULT_ACCEPTED
    assert not thread.is_alive() and not server.plant.link.process.alive()
    assert server.plant.rows and server.plant.link.tap.version.startswith("ArduRover")


def test_a_ground_station_takes_control_through_the_served_companion(tmp_path):
    """`sim serve --vehicle ardurover --policy companion`: the firmware's own stream and the companion's reach an
    ordinary ground station, which takes control through the companion (the lease the companion keeps)."""
    firmware = firmware_or_skip()
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(0.05)
    server = Server(load("tunnel"), "ardurover", 1, port=0, peers=(gcs.getsockname(),), perfect_link=True,
                    epochs_file=tmp_path / "returnlink.epochs", policy="companion", firmware=firmware, speedup=20.0)
    out = io.StringIO()
    thread = threading.Thread(target=server.serve, kwargs={"speedup": 20.0, "duration": 60.0, "out": out},
                              daemon=True)
    thread.start()
    gs = GroundStation(255, 190, target=1, target_comp=COMPANION_COMPID)
    parser = apm.MAVLink(None, srcSystem=255, srcComponent=190)
    heard: dict[int, object] = {}
    pending = None
    t0 = time.monotonic()
    owned = None  # the LEASE_STATUS that first showed the station as the owner
    try:
        # the station keeps its heartbeat going until the server's run ends, so the lease it took stays its own
        while thread.is_alive() and time.monotonic() - t0 < 90:
            now = (time.monotonic() - t0) * 20.0  # the station keeps its once-a-second cadence in simulated time
            for frame in gs.tick(now):
                gcs.sendto(frame, server.address)
            try:
                data, _ = gcs.recvfrom(65535)
            except TimeoutError:
                continue
            gs.feed(data, now)
            for m in parser.parse_buffer(data) or ():
                if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1:
                    heard[m.get_srcComponent()] = m
            if pending is None and gs.vehicle.status is not None:
                pending = gs.acquire()
            if owned is None and pending is not None and pending.done and gs.vehicle.status.owner == 255:
                owned = gs.vehicle.status
    finally:
        thread.join(90)
        gcs.close()
        server.close()
    assert heard[1].autopilot == apm.MAV_AUTOPILOT_ARDUPILOTMEGA  # the firmware's own heartbeat, relayed
    assert COMPANION_COMPID in heard  # and the companion's beside it
    assert pending is not None and pending.ok
    assert owned is not None and owned.state == mav.RETURNLINK_STATE_TELEOP
    assert not thread.is_alive() and not server.plant.link.process.alive()
    assert server.vehicle is not None and server.vehicle.book.owner == 255
    assert "lease teleop" in out.getvalue()  # the status line says who holds the lease


def test_a_plain_ground_station_meets_the_served_applet():
    """`sim serve --vehicle ardurover --policy applet`: the firmware boots with the Lua applet aboard (its ready
    text, said during the boot before any ground station is served), whose RLNK_ parameters an ordinary ground
    station reads through the radio proxy, and the vehicle-side radio's RADIO_STATUS is fed to the firmware once a
    second, as on a rover with a SiK radio."""
    from vehicle.applet import TEXT_PREFIX

    firmware = firmware_or_skip()
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(0.2)
    server = Server(load("tunnel"), "ardurover", 1, port=0, peers=(gcs.getsockname(),), policy="applet",
                    firmware=firmware, speedup=20.0)
    sent: list[float] = []
    feed = server.plant.radio_status
    server.plant.radio_status = lambda state, t: (sent.append(t), feed(state, t))
    thread = threading.Thread(target=server.serve, kwargs={"speedup": 20.0, "duration": 40.0, "out": io.StringIO()},
                              daemon=True)
    thread.start()
    mav = apm.MAVLink(None, srcSystem=255, srcComponent=190)
    timeout = None
    deadline = time.monotonic() + 90
    try:
        while time.monotonic() < deadline and timeout is None:
            try:
                data, _ = gcs.recvfrom(65535)
            except TimeoutError:
                continue
            for m in mav.parse_buffer(data) or ():
                kind = m.get_type()
                if kind == "HEARTBEAT" and m.get_srcSystem() == 1:
                    gcs.sendto(apm.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(mav), server.address)
                    if timeout is None:
                        gcs.sendto(apm.MAVLink_param_request_read_message(1, 1, b"RLNK_TIMEOUT", -1).pack(mav),
                                   server.address)
                elif kind == "PARAM_VALUE" and m.param_id == "RLNK_TIMEOUT":
                    timeout = m.param_value
    finally:
        thread.join(120)
        gcs.close()
        server.close()
    texts = [text for _t, text in server.plant.applet_texts]
    assert any(text.startswith(TEXT_PREFIX + "ready") for text in texts), texts
    assert timeout == pytest.approx(server.plant.rlnk["RLNK_TIMEOUT"])
    assert len(sent) >= 10 and all(b - a == pytest.approx(1.0, abs=0.05) for a, b in zip(sent, sent[1:], strict=False))
    assert not thread.is_alive() and not server.plant.link.process.alive()
