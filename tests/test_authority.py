"""Who may change the vehicle (docs/architecture.md §3.8-3.9), end to end through the MAVLink endpoint in simulated
time."""

from __future__ import annotations

import pytest

from tests.harness import Pair
from vehicle.app import State
from vehicle.lease_root import owner_stale
from vehicle.services.base import mav

OWNER, STRANGER = 255, 245


def owned(pair: Pair) -> Pair:
    """The owner acquires the vehicle and arms it; the stranger is connected too."""
    pair.connect()
    p = pair.stations[OWNER].acquire()
    pair.until(lambda: p.done, 2, "ACK")
    a = pair.stations[OWNER].arm()
    pair.until(lambda: a.done, 2, "arm ACK")
    assert p.ok and a.ok and pair.vehicle.book.owner == OWNER
    return pair


def texts(pair: Pair, sysid: int) -> list[str]:
    return [text for _, text in pair.stations[sysid].texts]


def test_a_stale_owner_is_not_taken_over_while_its_return_runs():
    """LEASE_STALE_TAKE=1: 4 s into the return a stranger asks for control and sends a command (auto-grant):
    both refused NOT_IN_CONTROL with "return in progress"; after the chain ends the silent owner is taken over."""
    pair = owned(Pair(stations=(OWNER, STRANGER)))
    epoch = pair.vehicle.book.epoch
    pair.stations[OWNER].drive_velocity(1.5, 0.0)
    pair.step(12.0)  # 15 m out, so the return takes a while
    pair.stations.pop(OWNER)  # the owner's link dies: nothing more arrives from it
    pair.until(lambda: pair.vehicle.state() == State.RETURNING, 5, "the return")
    pair.step(4.0)
    assert pair.vehicle.state() == State.RETURNING and owner_stale(pair.vehicle.book, pair.t)
    gs = pair.stations[STRANGER]
    take, arm = gs.acquire(), gs.arm(False)
    pair.until(lambda: take.done and arm.done, 2, "ACKs")
    assert take.result == mav.MAV_RESULT_NOT_IN_CONTROL and arm.result == mav.MAV_RESULT_NOT_IN_CONTROL
    assert sum("return in progress" in text for text in texts(pair, STRANGER)) >= 2
    book = pair.vehicle.book
    assert book.owner == OWNER and book.epoch == epoch and pair.vehicle.armed
    pair.until(lambda: pair.vehicle.state() == State.AWAITING_CLAIM, 120, "the end of the return chain")
    pair.step(3.5)  # past the retry window: a new request, not a retry of the refused one
    take = gs.acquire()
    pair.until(lambda: take.done, 2, "ACK")
    assert take.ok and pair.vehicle.book.owner == STRANGER and pair.vehicle.book.epoch != epoch


def _command_frame(command: int, *params: float, sysid: int = OWNER, confirmation: int = 0) -> bytes:
    enc = mav.MAVLink(None, sysid, 190)
    p7 = tuple(params) + (0.0,) * (7 - len(params))
    return enc.command_long_encode(1, 1, command, confirmation, *p7).pack(enc)


def test_a_late_copy_of_rtl_after_a_newer_command_is_answered_but_never_runs_again():
    """Mode RTL, then mode HOLD (the same command id, newer), then a late copy of the RTL: the copy gets the
    first answer and the lease is not expired a second time."""
    pair = owned(Pair(stations=(OWNER,)))
    pair.stations[OWNER].drive_velocity(1.0, 0.0)
    pair.step(5.0)
    pair.stations[OWNER].stop_streaming()
    rtl = _command_frame(mav.MAV_CMD_DO_SET_MODE, 1, 4, 5)
    hold = _command_frame(mav.MAV_CMD_DO_SET_MODE, 1, 4, 3)
    acks: list[int] = []
    pair.stations[OWNER].listeners.append(
        lambda m, t: acks.append(m.result) if m.get_type() == "COMMAND_ACK" and m.command == 176 else None)
    for frame in (rtl, hold, rtl):
        pair.raw.append(frame)
        pair.step(0.5)
    expires = [e for e in pair.vehicle.event_log if e.reason.name == "OPERATOR_EXPIRE"]
    assert len(expires) == 1
    assert acks == [mav.MAV_RESULT_ACCEPTED] * 3
    assert pair.vehicle.state() == State.TELEOP  # HOLD took the vehicle back and the old RTL did not undo it
    assert pair.endpoint.counters.command_retries == 1


def _count(pair: Pair, name: str, seconds: float) -> int:
    pair.heard.clear()
    pair.step(seconds)
    return sum(1 for f in pair.heard if pair.endpoint.parser.parse_buffer(f)[0].get_type() == name)


def test_a_stranger_cannot_change_telemetry_rates_of_an_owned_vehicle_but_may_read():
    pair = owned(Pair(stations=(OWNER, STRANGER)))
    gs, owner = pair.stations[STRANGER], pair.stations[OWNER]
    before = _count(pair, "LEASE_STATUS", 4.0), _count(pair, "ATTITUDE", 2.0)
    slow = gs.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_LEASE_STATUS, 3_333_333)
    pair.step(0.1)
    fast = gs.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, 19_230)
    pair.step(0.1)
    assert slow.result == mav.MAV_RESULT_DENIED and fast.result == mav.MAV_RESULT_DENIED
    assert sum("message interval from 245 refused" in text for text in texts(pair, STRANGER)) == 2
    after = _count(pair, "LEASE_STATUS", 4.0), _count(pair, "ATTITUDE", 2.0)
    assert after == before and after[0] >= 8  # still 2 Hz for everyone
    got = []
    gs.listeners.append(lambda m, t: got.append(m) if m.get_type() == "AUTOPILOT_VERSION" else None)
    read = gs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    pair.step(0.1)
    assert read.ok and got  # a single message is a read: answered to anyone
    mine = owner.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, 100_000)
    pair.step(0.1)
    assert mine.ok and 9 <= _count(pair, "ATTITUDE", 1.0) <= 11  # the owner may


@pytest.mark.interop
def test_strangers_cycling_source_ports_do_not_starve_the_owners_downlink():
    """`sim serve` on loopback: the owner acquires, then 20 strangers send from 20 source ports in turn. The owner
    keeps receiving the whole downlink: as many frames as the fixed peer, which nobody can evict."""
    import socket
    import time

    from link.transports import UdpTransport
    from tests.interop import ServedVehicle, wait_until

    fixed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    fixed.bind(("127.0.0.1", 0))
    fixed.setblocking(False)
    served = ServedVehicle("open", gcs_port=fixed.getsockname()[1])
    owner = UdpTransport(("127.0.0.1", 0))
    strangers = [UdpTransport(("127.0.0.1", 0)) for _ in range(20)]
    vehicle = ("127.0.0.1", served.port)
    enc = mav.MAVLink(None, 200, 190)
    try:
        heartbeat = enc.heartbeat_encode(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(enc)
        owner.send(enc.command_long_encode(1, 1, mav.MAV_CMD_REQUEST_OPERATOR_CONTROL, 0, 1, 0, 10, 0, 0, 0, 0)
                   .pack(enc), vehicle)
        wait_until(lambda: served.vehicle.book.owner == 200, 20, "the owner's acquire")
        wait_until(lambda: served.server.plant.pinned() == [owner.address], 20, "the owner's address pinned")
        other = mav.MAVLink(None, 100, 190)
        stranger_hb = other.heartbeat_encode(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(other)
        for s in strangers:  # fill the table with strangers before counting
            s.send(stranger_hb, vehicle)
        time.sleep(0.3)
        owner.receive(), _drain(fixed)
        got_owner = got_fixed = 0
        for k in range(120):  # about 1.8 s: a stranger every 15 ms, the owner's heartbeat once a second
            strangers[k % len(strangers)].send(stranger_hb, vehicle)
            if k % 66 == 0:
                owner.send(heartbeat, vehicle)
            time.sleep(0.015)
            got_owner += len(owner.receive())
            got_fixed += _drain(fixed)
        time.sleep(0.2)
        got_owner += len(owner.receive())
        got_fixed += _drain(fixed)
        assert served.vehicle.book.owner == 200
        assert got_fixed > 20 and got_owner >= 0.9 * got_fixed, (got_owner, got_fixed)
    finally:
        for t in (owner, *strangers):
            t.close()
        fixed.close()
        served.close()


def _drain(sock) -> int:
    n = 0
    while True:
        try:
            sock.recvfrom(65535)
        except BlockingIOError:
            return n
        n += 1
