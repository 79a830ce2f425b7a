"""`sim serve --vehicle ardurover`: the firmware in real time (here 20x) behind the radio proxy, answering an
ordinary pymavlink ground station on loopback."""

from __future__ import annotations

import io
import socket
import threading
import time

from pymavlink.dialects.v20 import ardupilotmega as apm

from sim.firmware.serve import FirmwareServer
from sim.scenario import load
from tests.firmware_helpers import firmware_or_skip


def test_a_plain_ground_station_hears_and_commands_the_served_firmware():
    firmware = firmware_or_skip()
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(0.2)
    server = FirmwareServer(load("tunnel"), 1, "ardupilot-hold", firmware, port=0, peers=(gcs.getsockname(),),
                            perfect_link=True, speedup=20.0, duration=40.0, out=io.StringIO())
    thread = threading.Thread(target=server.run, daemon=True)
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
    assert seen["heartbeat"].autopilot == apm.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert seen["ack"].result == apm.MAV_RESULT_ACCEPTED
    assert not thread.is_alive() and not server.link.process.alive()
    assert server.rows and server.link.tap.version.startswith("ArduRover")
