"""Who may change the vehicle (DESIGN §3.8-3.9), end to end through the MAVLink endpoint in simulated time."""

from __future__ import annotations

from tests.harness import Pair
from vehicle.app import State
from vehicle.mavlink import mav

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
    owner = pair.stations.pop(OWNER)  # the owner's link dies: nothing more arrives from it
    pair.until(lambda: pair.vehicle.state() == State.RETURNING, 5, "the return")
    pair.step(4.0)
    assert pair.vehicle.state() == State.RETURNING and pair.vehicle.book.owner_stale(pair.t)
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
    assert owner.sysid == OWNER
