"""The radio proxy on loopback, and `returnlink sim serve` started the way a user starts it."""

from __future__ import annotations

import subprocess
import sys
import time

from pymavlink import mavutil

from link.proxy import RadioProxy
from link.radio import Radio, RadioParams
from link.transports import UdpTransport
from tests.interop import free_udp_port


def _drain(sock: UdpTransport, seconds: float) -> list[bytes]:
    end, got = time.monotonic() + seconds, []
    while time.monotonic() < end:
        got += [d for d, _ in sock.receive()]
        time.sleep(0.01)
    return got


def test_proxy_delivers_in_range_and_drops_behind_a_wall():
    where = [(5.0, 0.0)]
    walls = {True: 200.0, False: 0.0}
    blocked = [False]
    radio = Radio(RadioParams(shadowing_db=0.0, jitter_ms=0.0), lambda a, b: walls[blocked[0]], seed=1)
    ground = UdpTransport(("127.0.0.1", 0))
    side = UdpTransport(("127.0.0.1", 0), peers=(ground.address,))
    proxy = RadioProxy(side, radio, (0.0, 0.0), 20.0, lambda: where[0])
    try:
        t = 0.0
        for _ in range(20):
            t += 0.02
            proxy.update(t)
            proxy.to_ground(b"frame", t)
            proxy.flush(t + 0.05)
        got = _drain(ground, 0.2)
        assert got.count(b"frame") == 20
        assert any(d[0] == 0xFD for d in got)  # RADIO_STATUS from the radio, MAVLink 2
        blocked[0] = True
        where[0] = (5.5, 0.0)
        for _ in range(20):
            t += 0.02
            proxy.update(t)
            proxy.to_ground(b"frame", t)
            proxy.flush(t + 0.05)
        assert b"frame" not in _drain(ground, 0.2)
        ground.send(b"up", side.address)
        time.sleep(0.05)
        assert proxy.from_ground(t + 1.0) == []  # the other way is dead too
    finally:
        ground.close()
        side.close()


def test_sim_serve_answers_and_leaves_a_plot(tmp_path):
    port = free_udp_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="returnlink")
    proc = subprocess.Popen([sys.executable, "-m", "sim.cli", "sim", "serve", "tunnel", "--port", "0", "--peer",
                             f"127.0.0.1:{port}", "--speedup", "4", "--duration", "12", "--out", str(tmp_path),
                             "--state", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        hb = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=20)
        assert hb is not None and hb.type == 10 and hb.autopilot == 0  # GROUND_ROVER, GENERIC
        status = gcs.recv_match(type="LEASE_STATUS", blocking=True, timeout=5)
        assert status is not None and status.state == 0  # nobody owns it yet
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        gcs.close()
    assert proc.returncode == 0, err
    assert "through the radio model" in err and "t=" in err
    assert (tmp_path / "trajectory.png").stat().st_size > 10_000


class _Loopback:
    """A transport stand-in: datagrams handed in by the test, datagrams sent kept in order."""

    def __init__(self) -> None:
        self.inbox: list[bytes] = []
        self.sent: list[bytes] = []

    def receive(self) -> list[tuple[bytes, tuple[str, int]]]:
        got, self.inbox = self.inbox, []
        return [(d, ("127.0.0.1", 0)) for d in got]

    def send(self, data: bytes) -> None:
        self.sent.append(data)


def test_proxy_keeps_the_order_of_each_direction_under_jitter():
    radio = Radio(RadioParams(shadowing_db=0.0, latency_ms=20.0, jitter_ms=15.0), lambda a, b: 0.0, seed=4)
    port = _Loopback()
    proxy = RadioProxy(port, radio, (0.0, 0.0), 20.0, lambda: (5.0, 0.0))  # type: ignore[arg-type]
    up, t = [], 0.0
    for k in range(300):
        t = round(t + 0.005, 9)
        proxy.update(t)
        port.inbox.append(b"u%d" % k)
        up += [data for data, _addr in proxy.from_ground(t)]
        proxy.to_ground(b"d%d" % k, t)
        proxy.flush(t)
    up += [data for data, _addr in proxy.from_ground(t + 1.0)]
    proxy.flush(t + 1.0)
    down = [d for d in port.sent if d.startswith(b"d")]
    for got in (up, down):
        numbers = [int(d[1:]) for d in got]
        assert len(numbers) > 250 and numbers == sorted(numbers)
