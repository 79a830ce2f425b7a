"""Companion mode against the real ArduPilot Rover firmware (SITL, its own physics), docs/architecture.md §11.

Each test starts its own firmware (on a free instance) and ``returnlink companion`` as processes and talks to the
companion over loopback UDP as ground stations do; an observer on the firmware's SERIAL0 tells what the rover did.
"""

from __future__ import annotations

import time

import pytest

from gcs.plans import parse_spec
from link import dialect
from tests.ardurover import Firmware
from tests.companion_live import CompanionProcess, LiveStation, firmware_companion, pump
from tests.interop import MAVProxy

pytestmark = pytest.mark.firmware

mav = dialect.load()
GUIDED, HOLD = 15, 4
RANGE_M = 15.0  # the test's radio: the operator is heard only within this of home


@pytest.fixture()
def rig(tmp_path):
    """The firmware booted, the companion on its SERIAL1, and the owner's station the companion sends to."""
    with firmware_companion(tmp_path) as r:
        yield r


def claim_and_arm(fw: Firmware, owner: LiveStation) -> None:
    p = owner.gs.acquire()
    pump([owner, fw], 5, lambda: p.done, "the operator-control answer")
    assert p.result == mav.MAV_RESULT_ACCEPTED
    owner.send_autopilot(lambda m: m.command_long_encode(1, 1, 176, 0, 1, GUIDED, 0, 0, 0, 0, 0))
    owner.send_autopilot(lambda m: m.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
    pump([owner, fw], 10, lambda: fw.armed and fw.mode == GUIDED, "GUIDED and armed, through the companion")


def test_claim_plan_stranger_refused_drive_out_silence_and_back_to_where_the_link_is(rig):
    fw, comp, owner = rig
    claim_and_arm(fw, owner)
    upload = owner.gs.upload(parse_spec("rtl:40:1"))  # the return plan (40 m, 1 m/s), to the companion (component 191)
    pump([owner, fw], 10, lambda: upload.done, "the plan's MISSION_ACK")
    assert upload.ok

    stranger = LiveStation(254, target_comp=1, peer=owner.peer)
    stranger.send_autopilot(lambda m: m.command_long_encode(1, 1, 176, 0, 1, HOLD, 0, 0, 0, 0, 0))
    pump([stranger, owner, fw], 5, lambda: any(c == 176 for _, c, _ in stranger.gs.acks), "the stranger's answer")
    assert [r for _, c, r in stranger.gs.acks if c == 176] == [mav.MAV_RESULT_NOT_IN_CONTROL]
    assert fw.mode == GUIDED  # it never reached the autopilot
    stranger.close()

    # the radio carries only RANGE_M from home: the operator drives on past it until the picture freezes, the
    # firmware stops the rover when the setpoints stop, and the companion, silent, takes it back
    owner.reach = lambda: fw.distance() < RANGE_M
    owner.velocity = (2.5, 0.0)
    pump([owner, fw], 40, lambda: fw.distance() >= RANGE_M + 1.0, "the rover out of the radio's range")
    owner.velocity = None
    pump([owner, fw], 10, lambda: fw.speed < 0.2, "the rover to stop out of range")
    out = fw.distance()
    pump([owner, fw], 30, lambda: fw.distance() < out - 3.0, "the rover to turn back")
    pump([owner, fw], 60, lambda: fw.mode == HOLD and fw.speed < 0.1, "the rover to stop in HOLD")
    pump([owner, fw], 2)
    rest = fw.distance()
    print(f"out {out:.1f} m, came to rest {rest:.1f} m from home (heard within {RANGE_M:g} m)")
    assert 3.0 < rest < RANGE_M, f"came to rest {rest:.1f} m from home: not where the link is, or all the way home"
    # the return ends where the link is: LINK_REGAINED, or COMPLETED at the place the link map vouches for when the
    # station's 1 Hz heartbeat had not yet confirmed the regain (three packets) on arrival
    reasons = [e.reason for e in owner.gs.events]
    assert "LINK_REGAINED" in reasons or "COMPLETED" in reasons
    assert owner.gs.vehicle.status.state == mav.RETURNLINK_STATE_AWAITING_CLAIM
    assert fw.mode == HOLD


def test_killing_the_companion_mid_drive_ends_in_the_firmwares_own_hold(rig):
    fw, comp, owner = rig
    claim_and_arm(fw, owner)
    owner.velocity = (2.0, 0.0)
    pump([owner, fw], 30, lambda: fw.distance() >= 8.0, "the rover 8 m out")
    comp.kill()
    killed = time.monotonic()
    pump([owner, fw], 15, lambda: fw.mode == HOLD, "the firmware's GCS failsafe to hold the rover")
    print(f"HOLD {time.monotonic() - killed:.1f} s after the companion was killed, {fw.distance():.1f} m out")
    assert any("GCS Failsafe" in t for t in fw.texts)
    pump([owner, fw], 5, lambda: fw.speed < 0.1, "the rover to stand still")


def test_check_and_configure_against_the_firmware(rig, capsys):
    fw, comp, owner = rig
    from sim.cli import main

    comp.stop()  # the check takes the companion's place on SERIAL1
    fw.observer.mav.param_set_send(1, 1, b"FS_GCS_ENABLE", 0, 2)
    pump([fw], 2)
    assert main(["companion", "--autopilot", f"tcp:127.0.0.1:{fw.serial1}", "--check"]) == 1
    assert "FS_GCS_ENABLE           0  1            DIFFERS" in capsys.readouterr().out
    assert main(["companion", "--autopilot", f"tcp:127.0.0.1:{fw.serial1}", "--configure"]) == 0
    assert "set FS_GCS_ENABLE 0 -> 1" in capsys.readouterr().out


def test_mavproxy_flies_the_rover_through_the_companion(tmp_path):
    fw = Firmware(tmp_path)
    mp = comp = None
    try:
        fw.boot()
        from tests.interop import free_udp_port

        port = free_udp_port()
        mp = MAVProxy(port, tmp_path, "mode,arm,rc,cmdlong,link,param")
        comp = CompanionProcess(["--autopilot", f"tcp:127.0.0.1:{fw.serial1}", "--gcs", f"udpout:127.0.0.1:{port}"],
                                tmp_path)
        # (90 s: a hang guard; MAVProxy's start-up once took over 30 s on a loaded 2-core machine)
        pump([fw], 90, lambda: "returnlink companion" in mp.text(), "MAVProxy to hear the companion")
        mp.say("arm throttle")  # a plain client: its first command makes it the owner (LEASE_AUTOGRANT)
        pump([fw], 15, lambda: fw.armed, "MAVProxy's arm to reach the firmware")
        mp.say("rc 3 1800")
        pump([fw], 30, lambda: fw.distance() > 5.0, "the rover to drive on MAVProxy's throttle")
        mp.say("rc 3 1500")
        mp.say("mode hold")
        pump([fw], 15, lambda: fw.mode == HOLD, "MAVProxy's mode change to reach the firmware")
        assert "lease" in mp.text()  # the companion's lease events reach an unmodified client
    finally:
        if mp is not None:
            mp.close()
        if comp is not None:
            comp.stop()
        fw.stop()
