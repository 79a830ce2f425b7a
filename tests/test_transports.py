"""Transports: real MAVLink bytes over loopback UDP and through the lockstep bus."""

from __future__ import annotations

import time

from link import dialect
from link.transports import LockstepBus, UdpTransport

rl = dialect.load()


def frame(seq_sys: int = 1) -> bytes:
    mav = rl.MAVLink(None, srcSystem=seq_sys, srcComponent=1)
    return rl.MAVLink_heartbeat_message(10, 8, 0, 0, 4, 3).pack(mav)


def receive_within(transport: UdpTransport, seconds: float = 1.0):
    """Poll a non-blocking socket for a bounded time (loopback delivery is not instant)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        got = transport.receive()
        if got:
            return got
        time.sleep(0.01)
    return []


def test_udp_answers_whoever_talks_to_it():
    vehicle = UdpTransport(("127.0.0.1", 0))
    gcs = UdpTransport(("127.0.0.1", 0), peers=(vehicle.address,))
    try:
        gcs.send(frame(255))
        got = receive_within(vehicle)
        assert got and got[0][1] == gcs.address
        vehicle.send(frame(1))  # to every learned peer
        back = receive_within(gcs)
        assert back
        msgs = rl.MAVLink(None).parse_buffer(back[0][0])
        assert msgs[0].get_type() == "HEARTBEAT" and msgs[0].get_srcSystem() == 1
    finally:
        vehicle.close()
        gcs.close()


def test_lockstep_delivers_in_time_order_per_destination():
    bus = LockstepBus()
    bus.send("gcs", "vehicle", b"b", at=0.04)
    bus.send("gcs", "vehicle", b"a", at=0.02)
    bus.send("vehicle", "gcs", b"x", at=0.01)
    bus.send("gcs", "vehicle", b"c", at=0.04)
    assert bus.receive("vehicle", 0.03) == [(b"a", "gcs")]
    assert bus.receive("vehicle", 0.05) == [(b"b", "gcs"), (b"c", "gcs")]
    assert bus.receive("gcs", 1.0) == [(b"x", "vehicle")]
    assert bus.pending() == 0
