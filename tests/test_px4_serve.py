"""`returnlink sim serve --vehicle px4rover` (issue 31 item 4): the real PX4 rover behind the radio proxy for a
ground station of one's own, here pymavlink on loopback: PX4's heartbeat reaches it through the proxy, it arms PX4
and is answered, the trajectory plot is written, and no PX4 process outlives the server. And the arguments that do
not go with PX4 exit 2 before anything starts."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from tests.firmware_helpers import px4_or_skip

pytestmark = [pytest.mark.interop, pytest.mark.firmware]

ROOT = Path(__file__).resolve().parents[1]


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _px4_dirs() -> set[str]:
    """The work directories of the PX4 processes alive now (``sim.px4.process``: one per PX4, removed at its stop)."""
    import tempfile

    return {str(p) for p in Path(tempfile.gettempdir()).glob("returnlink-px4-*")}


def _px4_commands() -> list[str]:
    """The command lines of the PX4 processes alive now."""
    out = subprocess.run(["pgrep", "-af", "bin/px4 -i"], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if line.strip()]


def _serve(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sim.cli", "sim", "serve", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=60)


def _env(**more: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), **more}


def test_a_ground_station_of_ones_own_arms_px4_through_the_proxy(tmp_path):
    px4 = px4_or_skip()
    gcs_port, port = _free_udp_port(), _free_udp_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{gcs_port}", source_system=255, source_component=190)
    out = tmp_path / "out"
    before = _px4_dirs()
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim.cli", "sim", "serve", "tunnel", "--vehicle", "px4rover", "--policy", "px4-hold",
         "--px4", str(px4), "--port", str(port), "--peer", f"127.0.0.1:{gcs_port}", "--perfect-link", "--speedup",
         "2", "--duration", "40", "--out", str(out)],
        cwd=ROOT, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        heard, acked, deadline, next_hb = None, None, time.monotonic() + 60, 0.0
        while time.monotonic() < deadline and acked is None and proc.poll() is None:
            now = time.monotonic()
            if now >= next_hb:  # 4 Hz wall, 2 Hz simulated at --speedup 2: PX4 counts it as its data link
                next_hb = now + 0.25
                gcs.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            m = gcs.recv_match(blocking=True, timeout=0.05)
            if m is None:
                continue
            if m.get_type() == "HEARTBEAT" and m.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4 and heard is None:
                heard = m
                gcs.target_system, gcs.target_component = m.get_srcSystem(), m.get_srcComponent()
            if heard is not None and m.get_type() in ("HEARTBEAT", "SYS_STATUS") and acked is None:
                gcs.mav.command_long_send(gcs.target_system, gcs.target_component,
                                          mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            if m.get_type() == "COMMAND_ACK" and m.command == mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM \
                    and m.result == mavutil.mavlink.MAV_RESULT_ACCEPTED:
                acked = m
        assert heard is not None, "no PX4 heartbeat came through the proxy"
        assert acked is not None, "PX4 did not accept the arming"
        stdout, stderr = proc.communicate(timeout=60)  # --duration 40 simulated s ends it
        assert proc.returncode == 0, stderr
        assert "ready after" in stderr and (out / "trajectory.png").stat().st_size > 10_000
        assert (out / "px4.log").exists()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=30)
        gcs.close()
    # the server's PX4 (its instance, which its log names first) is gone, process and work directory
    first = (out / "px4.log").read_text(errors="replace").splitlines()[0]
    assert first.startswith("INFO  [px4] instance: ")
    mine = f"returnlink-px4-{first.rsplit(' ', 1)[1]}-"
    assert not [d for d in _px4_dirs() - before if mine in d]
    assert not [cmd for cmd in _px4_commands() if mine in cmd]


@pytest.mark.parametrize("args, says", [
    (["--vehicle", "rover", "--px4", "/nowhere"], "--px4 goes with --vehicle px4rover"),
    (["--vehicle", "px4rover", "--policy", "ardupilot-hold"], "px4rover"),
    (["--vehicle", "px4rover", "--firmware", "/nowhere/ardurover"], "--firmware goes with --vehicle ardurover"),
    (["--vehicle", "px4rover", "--params", "x.parm"], "PX4 keeps its parameters"),
    (["--vehicle", "px4rover", "--px4", "/nowhere"], "/nowhere"),
])
def test_what_does_not_go_with_px4_exits_2_naming_it(args, says):
    done = _serve(["tunnel", *args, "--duration", "1"], _env(RETURNLINK_PX4=""))
    assert done.returncode == 2, done.stderr
    assert says in done.stderr and "Traceback" not in done.stderr


def test_no_px4_at_all_names_both_ways_to_give_one():
    done = _serve(["tunnel", "--vehicle", "px4rover", "--duration", "1"], _env(RETURNLINK_PX4=""))
    assert done.returncode == 2
    assert "--px4" in done.stderr and "RETURNLINK_PX4" in done.stderr and "Traceback" not in done.stderr


def test_a_ground_station_takes_control_through_the_companion_beside_served_px4(tmp_path):
    """`sim serve --vehicle px4rover --policy companion`: PX4's own stream and the companion's reach an ordinary
    ground station, which takes control through the companion (the lease the companion keeps)."""
    import io
    import threading

    from pymavlink.dialects.v20 import ardupilotmega as apm

    from gcs.station import GroundStation
    from gcs.station import mav as gmav
    from sim.scenario import load
    from sim.serve import Server
    from vehicle.companion.router import COMPANION_COMPID

    px4 = px4_or_skip()
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(0.05)
    speedup = 5.0
    server = Server(load("tunnel"), "px4rover", 1, port=0, peers=(gcs.getsockname(),), perfect_link=True,
                    epochs_file=tmp_path / "returnlink.epochs", policy="companion", px4=px4)
    out = io.StringIO()
    thread = threading.Thread(target=server.serve, kwargs={"speedup": speedup, "duration": 40.0, "out": out},
                              daemon=True)
    thread.start()
    gs = None  # addressed once the companion is heard: PX4's system id is its instance's (MAV_SYS_ID)
    parser = apm.MAVLink(None, srcSystem=255, srcComponent=190)
    heard: dict[int, object] = {}
    pending, owned, t0 = None, None, time.monotonic()
    try:
        while thread.is_alive() and time.monotonic() - t0 < 90:
            now = (time.monotonic() - t0) * speedup  # the station's once-a-second cadence in simulated time
            for frame in gs.tick(now) if gs is not None else ():
                gcs.sendto(frame, server.address)
            try:
                data, _ = gcs.recvfrom(65535)
            except TimeoutError:
                continue
            for m in parser.parse_buffer(data) or ():
                if m.get_type() == "HEARTBEAT":
                    heard[m.get_srcComponent()] = m
                    if gs is None and m.get_srcComponent() == COMPANION_COMPID:
                        gs = GroundStation(255, 190, target=m.get_srcSystem(), target_comp=COMPANION_COMPID)
            if gs is None:
                continue
            gs.feed(data, now)
            if pending is None and gs.vehicle.status is not None:
                pending = gs.acquire()
            if owned is None and pending is not None and pending.done and gs.vehicle.status.owner == 255:
                owned = gs.vehicle.status
    finally:
        thread.join(90)
        gcs.close()
        server.close()
    assert any(m.autopilot == apm.MAV_AUTOPILOT_PX4 for m in heard.values())  # PX4's own heartbeat, relayed
    assert COMPANION_COMPID in heard  # and the companion's beside it
    assert pending is not None and pending.ok
    assert owned is not None and owned.state == gmav.RETURNLINK_STATE_TELEOP
    assert not thread.is_alive() and not server.plant.link.process.alive()
    assert "lease teleop" in out.getvalue()
