"""MAVLink manners: what common ground stations expect of any vehicle, answered without pretending to be another
autopilot: an FTP NAK, the standard modes microservice, and .tlog timestamps with a real date."""

from __future__ import annotations

import struct

import pytest
from pymavlink.dialects.v20 import development as dev

from link.ftp import ERR_FILE_NOT_FOUND
from link.ftp import OP_NAK as FTP_NAK
from link.ftp import OP_OPEN_FILE_RO as FTP_OPEN_FILE_RO
from tests.harness import Pair
from vehicle.modes import AVAILABLE_MODES, PX4_AUTO, PX4_AUTO_LOITER, PX4_AUTO_RTL, PX4_POSCTL
from vehicle.params import SPECS
from vehicle.services.base import mav


def sent(pair: Pair, kind: str) -> list:
    """Every message of ``kind`` the vehicle sent, decoded with MAVLink's development dialect."""
    parser = dev.MAVLink(None)
    parser.robust_parsing = True
    out = []
    for frame in pair.heard:
        for m in parser.parse_buffer(frame) or []:
            if m.get_type() == kind:
                out.append(m)
    return out


def test_ftp_request_is_answered_with_a_nak_at_once():
    """MAVProxy asks for @PARAM/param.pck over FTP at connect; a NAK (the vehicle offers no such file) makes it use
    the parameter protocol now."""
    pair = Pair()
    pair.step(0.1)
    req = struct.pack("<HBBBBBBI", 41, 3, FTP_OPEN_FILE_RO, 11, 0, 0, 0, 0) + b"@PARAM/param.pck"
    enc = mav.MAVLink(None, 255, 190)
    pair.raw.append(enc.file_transfer_protocol_encode(0, 1, 1, req + bytes(251 - len(req))).pack(enc))
    pair.heard.clear()
    pair.step()
    naks = sent(pair, "FILE_TRANSFER_PROTOCOL")
    assert len(naks) == 1
    m = naks[0]
    seq, session, opcode, size, req_opcode = struct.unpack_from("<HBBBB", bytes(m.payload))
    assert (m.target_system, m.target_component) == (255, 190)
    assert (seq, session, opcode, size, req_opcode) == (42, 3, FTP_NAK, 1, FTP_OPEN_FILE_RO)
    assert bytes(m.payload)[12] == ERR_FILE_NOT_FOUND


def test_ftp_answers_are_never_answered():
    pair = Pair()
    pair.step(0.1)
    nak = struct.pack("<HBBBBBBI", 1, 0, FTP_NAK, 1, FTP_OPEN_FILE_RO, 0, 0, 0) + b"\x07"
    enc = mav.MAVLink(None, 255, 190)
    pair.raw.append(enc.file_transfer_protocol_encode(0, 1, 1, nak + bytes(251 - len(nak))).pack(enc))
    pair.heard.clear()
    pair.step()
    assert sent(pair, "FILE_TRANSFER_PROTOCOL") == []


def test_available_modes_lists_every_mode_the_heartbeat_can_show():
    pair = Pair()
    pair.step(0.1)
    pair.heard.clear()
    p = pair.gs.command(mav.MAV_CMD_REQUEST_MESSAGE, dev.MAVLINK_MSG_ID_AVAILABLE_MODES, 0)
    pair.step(0.1)
    assert p.ok
    modes = sent(pair, "AVAILABLE_MODES")
    assert [m.mode_index for m in modes] == [1, 2, 3, 4] and {m.number_modes for m in modes} == {4}
    by_custom = {m.custom_mode: m for m in modes}
    teleop = by_custom[PX4_POSCTL << 16]
    assert teleop.standard_mode == dev.MAV_STANDARD_MODE_NON_STANDARD and teleop.mode_name == "TELEOP"
    hold = by_custom[(PX4_AUTO << 16) | (PX4_AUTO_LOITER << 24)]
    assert hold.standard_mode == dev.MAV_STANDARD_MODE_POSITION_HOLD and hold.mode_name == ""
    ret = by_custom[(PX4_AUTO << 16) | (PX4_AUTO_RTL << 24)]
    assert ret.standard_mode == dev.MAV_STANDARD_MODE_SAFE_RECOVERY
    pair.heard.clear()
    one = pair.gs.command(mav.MAV_CMD_REQUEST_MESSAGE, dev.MAVLINK_MSG_ID_AVAILABLE_MODES, 3)
    pair.step(0.1)
    assert one.ok and [m.mode_index for m in sent(pair, "AVAILABLE_MODES")] == [3]
    bad = pair.gs.command(mav.MAV_CMD_REQUEST_MESSAGE, dev.MAVLINK_MSG_ID_AVAILABLE_MODES, len(AVAILABLE_MODES) + 1)
    pair.step(0.1)
    assert bad.result == mav.MAV_RESULT_DENIED


def test_current_mode_follows_the_heartbeat_on_change_and_on_request():
    pair = Pair()
    pair.connect()
    p = pair.gs.acquire()
    pair.until(lambda: p.done, 2, "ACK")
    pair.step(0.2)
    current = sent(pair, "CURRENT_MODE")
    assert current and current[-1].custom_mode == pair.endpoint.custom_mode()  # what the heartbeat shows
    story = [("hold", pair.gs.hold, (PX4_AUTO << 16) | (PX4_AUTO_LOITER << 24), dev.MAV_STANDARD_MODE_POSITION_HOLD),
             ("drive", lambda: pair.gs.drive_velocity(0.5, 0.0), PX4_POSCTL << 16, dev.MAV_STANDARD_MODE_NON_STANDARD),
             ("rtl", pair.gs.rtl, (PX4_AUTO << 16) | (PX4_AUTO_RTL << 24), dev.MAV_STANDARD_MODE_SAFE_RECOVERY)]
    for what, act, custom, standard in story:
        pair.heard.clear()
        act()
        pair.until(lambda c=custom: pair.endpoint.custom_mode() == c, 1, what)
        pair.step(0.1)
        changed = [(m.custom_mode, m.standard_mode) for m in sent(pair, "CURRENT_MODE")]
        # once per change, not a stream (a return on this short trail may already have ended: another change)
        assert changed[0] == (custom, standard), what
        assert all(a != b for a, b in zip(changed, changed[1:], strict=False)), what
    pair.gs.stop_streaming()
    pair.heard.clear()
    q = pair.gs.command(mav.MAV_CMD_REQUEST_MESSAGE, dev.MAVLINK_MSG_ID_CURRENT_MODE)
    pair.step(0.1)
    assert q.ok and len(sent(pair, "CURRENT_MODE")) == 1


def test_lockstep_tlog_is_stamped_from_2026_plus_sim_time(tmp_path):
    import datetime

    from pymavlink import mavutil

    from sim.runner import Run, write_tlog
    from sim.scenario import load

    sc = load("open")
    run = Run(sc, "rover", 3, duration=4.0)
    run.run()
    path = write_tlog(run, tmp_path / "run.tlog")
    log = mavutil.mavlink_connection(str(path), dialect="returnlink")
    stamps = []
    while (m := log.recv_match()) is not None:
        stamps.append(m._timestamp)
    start = datetime.datetime(2026, 1, 1, tzinfo=datetime.timezone.utc).timestamp()
    assert stamps and start <= stamps[0] < start + 1.0
    assert stamps[-1] <= start + 4.0 + 1e-6 and stamps == sorted(stamps)


@pytest.mark.interop
def test_mavproxy_with_its_default_modules_gets_parameters_without_an_ftp_time_out(tmp_path):
    """MAVProxy's default module set includes ftp, and its param module asks for @PARAM/param.pck first."""
    from tests.interop import MAVProxy, ServedVehicle

    served = ServedVehicle("tunnel")
    mp = MAVProxy(served.gcs_port, tmp_path)  # its default modules, ftp among them
    try:
        mp.wait_for_parameters(len(SPECS))
    finally:
        mp.close()
        served.close()
    log = mp.log
    assert "FTP: request timed out" not in log.read_text()
