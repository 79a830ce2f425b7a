"""Every PX4 a test or a run starts speaks only to ports of its own (docs/architecture.md §10.1): PX4's own start-up
script sends its GCS link to UDP 14550 (every ground station's, the companion walkthrough's) and its API link to
14540+N (MAVSDK's) until a partner talks, so a PX4 running beside the walkthrough once fed it PX4's heartbeats. Each
run lays its own copy of that script with ``-o`` ports of the run's own (``sim.px4.process.mavlink_rc``).

The script rewrite is checked on PX4's own text; the real PX4 (from $RETURNLINK_PX4, else the shared tree, as in
test_px4_bridge.py) is checked to send its first frames, before anyone has said a word to it, to the ports the run
named."""

from __future__ import annotations

import contextlib
import socket
import time

import pytest
from pymavlink.dialects.v20 import common as mav

from sim.px4.bridge import HilBridge
from sim.px4.hil import RoverState
from sim.px4.process import API_REMOTE_PORT, MAVLINK_RC, PX4Process, claim_instance, mavlink_rc
from tests.firmware_helpers import group_gone, px4_or_skip
from tests.test_px4_bridge import DT, ORIGIN, Station

pytestmark = [pytest.mark.interop, pytest.mark.firmware]

STILL = RoverState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_the_mavlink_script_names_the_runs_own_ports_and_leaves_the_rest():
    px4_dir = px4_or_skip()
    text = (px4_dir / "etc" / "init.d-posix" / MAVLINK_RC).read_text()
    ours = mavlink_rc(text, 40001, 40002)
    assert ours is not None
    changed = [(a, b) for a, b in zip(text.splitlines(), ours.splitlines(), strict=True) if a != b]
    assert len(changed) == 2, changed
    (gcs_was, gcs), (api_was, api) = changed
    assert gcs == gcs_was + " -o 40001" and "$udp_gcs_port_local" in gcs
    assert api == api_was.replace("-o $udp_offboard_port_remote", "-o 40002")
    assert mavlink_rc("echo another PX4\n", 1, 2) is None  # nothing to change: the tree's own script runs


def test_a_silent_px4_speaks_to_the_runs_own_ports_only():
    """Nobody talks to PX4: its GCS link's frames reach the port the run named, its API link's 18370+N."""
    px4_dir = px4_or_skip()
    n, server = claim_instance()
    gcs = Station(n)  # never sends: only listens, and reads PX4's clock for the bridge
    api = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    api.bind(("127.0.0.1", API_REMOTE_PORT + n))
    api.setblocking(False)
    bridge = HilBridge(server, ORIGIN, clock=gcs.poll, watch=[gcs.sock])
    p = PX4Process(px4_dir, n, gcs_port=gcs.sock.getsockname()[1]).start()
    api_heard = b""
    try:
        assert p.remote_ports == (gcs.sock.getsockname()[1], API_REMOTE_PORT + n)
        bridge.accept(alive=p.alive)
        deadline = time.monotonic() + 60.0  # a bound on a broken run, not a measurement
        while (gcs.heartbeat is None or not api_heard) and time.monotonic() < deadline:
            bridge.step(STILL, DT)
            gcs.poll()
            with contextlib.suppress(BlockingIOError):
                api_heard += api.recv(65536)
    finally:
        p.stop()
        bridge.close()
        api.close()
        gcs.sock.close()
    assert gcs.heartbeat is not None and gcs.heartbeat.type == mav.MAV_TYPE_GROUND_ROVER, p.log_tail()
    assert api_heard, "PX4's API link never spoke to the run's own port"
    assert group_gone(p.pid)
