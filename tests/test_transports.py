"""Transports: real MAVLink bytes over loopback UDP and through the lockstep bus."""

from __future__ import annotations

import time

import pytest

from link import dialect
from link.transports import LockstepBus, UdpTransport

pytestmark = pytest.mark.interop

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


def test_an_inbox_head_says_exactly_when_receive_has_something():
    """The lockstep loop skips ``receive`` while the inbox's head is not due: that must be exactly when receive
    would return nothing, for every time around each arrival."""
    bus = LockstepBus()
    inbox = bus.inbox("vehicle")
    assert inbox == [] and bus.inbox("vehicle") is inbox
    for at in (0.06, 0.02, 0.04, 0.04):
        bus.send("gcs", "vehicle", b"%.2f" % at, at)
    for now in (0.0, 0.019, 0.02, 0.03, 0.04, 0.05, 0.059, 0.06, 0.07):
        due = bool(inbox) and inbox[0][0] <= now
        got = bus.receive("vehicle", now)
        assert due == bool(got), now
    assert inbox == [] and bus.pending() == 0


def test_strangers_cycling_ports_never_evict_a_pinned_peer():
    """17+ source ports would push a 16-entry table's oldest peer out; the owner's address is pinned."""
    owner = UdpTransport(("127.0.0.1", 0))
    pins: set = set()
    vehicle = UdpTransport(("127.0.0.1", 0), max_peers=16, pinned=lambda: pins)
    strangers = [UdpTransport(("127.0.0.1", 0)) for _ in range(20)]
    try:
        owner.send(frame(255), vehicle.address)
        assert receive_within(vehicle)[0][1] == owner.address
        pins.add(owner.address)  # the vehicle says: this one owns me
        for s in strangers * 2:
            s.send(frame(7), vehicle.address)
        end = time.monotonic() + 2.0
        heard = set()
        while len(heard) < len(strangers) and time.monotonic() < end:
            heard |= {addr for _, addr in vehicle.receive()}
            time.sleep(0.01)
        assert len(heard) == len(strangers)
        assert owner.address in vehicle.learned and len(vehicle.learned) == 16
        assert strangers[-1].address in vehicle.learned  # strangers still share the rest of the table
        vehicle.learned.remove(owner.address)  # even when it was never (re)learned, a pinned peer is sent to
        vehicle.send(frame(1))
        assert receive_within(owner)
    finally:
        for t in (owner, vehicle, *strangers):
            t.close()


def test_ready_says_whether_a_datagram_waits_and_is_false_once_closed():
    """The readiness the vehicle loop waits on between ticks: False with nothing to read, True once a datagram is
    there (and it stays there for ``receive``), False on a closed socket instead of raising."""
    vehicle = UdpTransport()
    gcs = UdpTransport(peers=(vehicle.address,))
    try:
        assert vehicle.ready(0.0) is False
        gcs.send(b"ping")
        assert vehicle.ready(2.0) is True
        assert [data for data, _ in vehicle.receive()] == [b"ping"]
        assert vehicle.ready(0.0) is False
    finally:
        gcs.close()
        vehicle.close()
    assert vehicle.ready(0.0) is False
