"""The radio proxy on loopback, and `returnlink sim serve` started the way a user starts it."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
from pymavlink import mavutil

from link.proxy import RadioProxy
from link.radio import Radio, RadioParams
from link.transports import UdpTransport
from tests.interop import free_udp_port

pytestmark = pytest.mark.interop


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


class _FakeLink:
    """The server's UDP side in memory: a COMMAND_LONG waiting at one moment of the injected clock, and every
    datagram the server sends with the clock reading at that moment."""

    def __init__(self, clock: list[float], frame: bytes, at: float) -> None:
        self.clock, self.frame, self.at = clock, frame, at
        self.received_at: float | None = None
        self.sent: list[tuple[float, bytes]] = []

    def receive(self, max_packets: int = 256) -> list[tuple[bytes, tuple[str, int]]]:
        if self.received_at is None and self.clock[0] >= self.at:
            self.received_at = self.clock[0]
            return [(self.frame, ("127.0.0.1", 14550))]
        return []

    def send(self, data: bytes, to=None) -> None:
        self.sent.append((self.clock[0], data))


def test_sim_serve_answers_a_command_in_the_tick_it_arrived():
    """docs/architecture.md §8: a COMMAND_LONG read at one tick is answered before the loop sleeps toward the next (the
    clock is injected: simulated time only)."""
    from sim.scenario import load
    from sim.serve import Server
    from vehicle.services.base import mav

    server = Server(load("open"), port=0, peers=(), perfect_link=True)
    gcs = mav.MAVLink(None, 255, 190)
    cmd = gcs.command_long_encode(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs)
    now = [50.0]
    link = _FakeLink(now, cmd, at=50.3)
    server.proxy.transport = link

    def sleep(s: float) -> None:
        now[0] += s

    try:
        server.serve(duration=0.6, clock=lambda: now[0], sleep=sleep, out=None)
    finally:
        server.close()
    assert link.received_at is not None
    parser = mav.MAVLink(None, 0, 0)
    acks = [(at, m) for at, data in link.sent for m in parser.parse_buffer(data) or []
            if m.get_type() == "COMMAND_ACK"]
    assert [m.command for _, m in acks] == [mav.MAV_CMD_REQUEST_MESSAGE]
    assert acks[0][0] == link.received_at  # no sleep between the command read and its answer: the same tick


def test_sim_serve_answers_a_command_arriving_between_ticks_at_once():
    """With ``wait`` (the UDP socket's readiness in `sim serve`) a COMMAND_LONG arriving 5 ms into the wait for the
    next tick is answered then, through the radio proxy, not at the next tick (injected clock: simulated time)."""
    from sim.scenario import load
    from sim.serve import Server
    from vehicle.services.base import mav

    server = Server(load("open"), port=0, peers=(), perfect_link=True)
    gcs = mav.MAVLink(None, 255, 190)
    cmd = gcs.command_long_encode(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs)
    now = [50.0]
    link = _FakeLink(now, cmd, at=50.305)  # ticks start at 50.30 and 50.32
    server.proxy.transport = link
    tick_clocks: list[float] = []

    def wait(timeout: float) -> bool:
        if link.received_at is None and now[0] < link.at <= now[0] + timeout:
            now[0] = link.at
            return True
        now[0] += timeout
        return False

    def tick_clock(t: float, tick=server.plant.tick) -> None:
        tick_clocks.append(now[0])
        tick(t)

    server.plant.tick = tick_clock
    try:
        server.serve(duration=0.6, clock=lambda: now[0], sleep=lambda s: None, out=None, wait=wait)
    finally:
        server.close()
    parser = mav.MAVLink(None, 0, 0)
    acks = [at for at, data in link.sent for m in parser.parse_buffer(data) or [] if m.get_type() == "COMMAND_ACK"]
    assert link.received_at == 50.305 and acks == [50.305]  # answered the moment it came, between two ticks
    assert not any(abs(c - 50.305) < 1e-9 for c in tick_clocks)
