"""docs/architecture.md §6 "Where the return ends", one story per rule, on the whole vehicle (MAVLink both ways,
simulated robot, perfect radio that a test can cut): time is advanced by hand and the decision checked after each step.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.harness import Pair
from vehicle.app import DT, State
from vehicle.lease import ExpireReason


def acquired(pair: Pair) -> Pair:
    return pair.take_control()


def reasons(pair: Pair, since: float = 0.0) -> list[tuple[float, ExpireReason]]:
    return [(e.t, e.reason) for e in pair.vehicle.event_log if e.t >= since and e.reason is not ExpireReason.NONE]


def one_in(n: int, since: float):
    """A radio that, from ``since`` on, delivers one frame in ``n`` (the sequence numbers show the rest lost)."""
    count = [0]

    def lose(sysid: int, t: float) -> bool:
        if t < since:
            return False
        count[0] += 1
        return count[0] % n != 0

    return lose


def drive(pair: Pair, speed: float, seconds: float) -> None:
    pair.gs.drive_velocity(speed, 0.0)
    pair.step(seconds)


def test_a_return_over_a_good_link_lays_good_crumbs_and_a_later_loss_does_not_drive_away():
    """Rule 1: crumbs laid while a service block holds the lease carry their true tag."""
    pair = acquired(Pair())
    v = pair.vehicle
    v.set_param("RTL_MAX_DISP", 6.0)
    drive(pair, 1.0, 20.0)
    pair.gs.stop()  # the operator keeps streaming (zero velocity): the link stays good
    pair.step(1.0)
    p = pair.gs.rtl()
    pair.step(0.2)
    assert p.ok and v.state() == State.RETURNING
    pair.until(lambda: v.state() == State.AWAITING_CLAIM, 30, "the commanded return to end")
    x_far = max(x for x, _ in [pair.driver.pose[:2]])
    x_end = pair.driver.pose[0]
    assert x_end < 18.0  # it came back about 6 m toward the operator
    t_loss = pair.t
    pair.lose = lambda sysid, t: True  # now the link dies for good
    pair.until(lambda: any(r is ExpireReason.COMMS_LOST for _, r in reasons(pair, t_loss)), 5, "COMMS_LOST")
    xs = []
    for _ in range(int(20 / DT)):
        pair.step()
        xs.append(pair.driver.pose[0])
    assert max(xs) <= x_end + 0.5, f"drove away from the operator: {x_end:.1f} -> {max(xs):.1f} m (far {x_far:.1f})"


@pytest.mark.parametrize("outage", [4.0, 8.0])
def test_link_regained_one_regain_s_after_the_link_is_back(outage):
    """Rule 3: LINK_REGAINED fires LNK_REGAIN_S after the link is good again, however long the outage (the
    station's sequence numbers run on while its packets are lost)."""
    pair = acquired(Pair())
    drive(pair, 1.0, 12.0)  # a trail longer than the return can back up during the outage
    pair.gs.stop()
    pair.step(1.0)
    t0 = pair.t
    back = t0 + outage
    pair.lose = lambda sysid, t: t0 <= t < back - 1e-9
    flips = []  # when the vehicle's view of the owner's link went lost -> up
    for _ in range(int((outage + 4.0) / DT)):
        was = pair.vehicle.book.link.lost
        pair.step()
        if was and not pair.vehicle.book.link.lost:
            flips.append(pair.t)
    got = reasons(pair, t0)
    assert [r for _, r in got][:1] == [ExpireReason.COMMS_LOST]
    assert len(flips) == 1, flips
    regain_s = pair.vehicle.params["LNK_REGAIN_S"]
    # the first packet after the outage comes within one teleop period (0.1 s), the trigger within a tick
    assert back + regain_s - 1e-9 <= flips[0] <= back + regain_s + 0.1 + DT + 1e-9, (back, flips)
    # the return block was still looking for the link, so it ended with it: at once where the link map vouches
    # for the place, else after the few metres to one it does (the outage taught it the places driven through);
    # or, a long outage, it reached the place the map vouches for first and stays there (LNK_MAP_SEEK 0: the place
    # held the link, what is missing is the station), where the link then comes back
    ended = [(t, r) for t, r in got if r in (ExpireReason.LINK_REGAINED, ExpireReason.COMPLETED)]
    assert ended, got
    t_end, why = ended[0]
    if why is ExpireReason.LINK_REGAINED:
        assert flips[0] - 1e-9 <= t_end <= flips[0] + 1.0, (flips, got)
    else:
        assert t_end <= flips[0] and pair.vehicle.linkmap.reliable(*pair.vehicle.estimator.pose[:2]), (flips, got)


def test_timeout_below_good_s_does_not_make_lost_and_regained_alternate():
    """Rule 4: any valid combination works; LNK_TIMEOUT 0.5 s below LNK_GOOD_S 1.5 s."""
    pair = acquired(Pair())
    pair.vehicle.set_param("LNK_TIMEOUT", 0.5)
    drive(pair, 1.0, 5.0)
    pair.gs.stop()
    pair.step(1.0)
    t0 = pair.t
    pair.lose = lambda sysid, t: t0 <= t < t0 + 0.8
    pair.step(4.0)
    got = reasons(pair, t0)
    assert [r for _, r in got] == [ExpireReason.COMMS_LOST, ExpireReason.LINK_REGAINED], got
    assert got[1][0] - (t0 + 0.8) >= pair.vehicle.params["LNK_REGAIN_S"] - 1e-9


def test_marginal_delivery_is_a_lost_link():
    """LNK_MIN_Q: one packet in eight gets through; the lucky packets must not keep the lease alive."""
    pair = acquired(Pair())
    drive(pair, 1.0, 5.0)
    t0 = pair.t
    pair.lose = one_in(8, t0)
    pair.step(8.0)
    got = reasons(pair, t0)
    assert got and got[0][1] is ExpireReason.COMMS_LOST, got
    assert got[0][0] <= t0 + pair.vehicle.params["LNK_TIMEOUT"] + 1.0


def test_marginal_delivery_with_min_q_zero_keeps_the_lease():
    pair = acquired(Pair())
    pair.vehicle.set_param("LNK_MIN_Q", 0.0)
    drive(pair, 1.0, 5.0)
    t0 = pair.t
    pair.lose = one_in(8, t0)
    pair.step(8.0)
    assert reasons(pair, t0) == []


def commanded_return_pace(pair: Pair) -> np.ndarray:
    """Stop, command RTL, and the speed back along -x over every second of the return (m/s)."""
    pair.gs.stop()
    pair.step(1.0)
    p = pair.gs.rtl()
    pair.step(0.2)
    v = pair.vehicle
    assert p.ok and v.state() == State.RETURNING
    xs = []
    while v.state() == State.RETURNING and len(xs) < int(30 / DT):
        pair.step()
        xs.append(pair.driver.pose[0])
    return np.convolve(-np.diff(xs) / DT, np.ones(50) / 50, mode="valid")


def test_return_speed_is_the_speed_driven_outbound_on_that_stretch():
    """Rule 5: RTL_SPEED=0 means the speed of the stretch being retraced, not the last second of teleop."""
    pair = acquired(Pair())
    v = pair.vehicle
    v.set_param("RTL_MAX_DISP", 12.0)
    drive(pair, 1.2, 15.0)
    drive(pair, 0.3, 2.0)  # the last second of teleop was slow
    per_second = commanded_return_pace(pair)
    assert per_second.max() >= 1.0, f"came back at {per_second.max():.2f} m/s on a stretch driven at 1.2"
    assert per_second.max() <= 2.0 + 0.05  # within the robot's limits


def test_a_stretch_driven_in_stutters_is_retraced_at_the_pace_driven_not_at_its_average():
    """Rule 5 through a fading link: teleop that arrives in bursts drives a straight stretch at 1.2 m/s in starts
    and stops; the stretch's length over its time is half that, and a return at it fell behind every baseline."""
    pair = acquired(Pair())
    v = pair.vehicle
    v.set_param("RTL_MAX_DISP", 12.0)
    for _ in range(8):
        drive(pair, 1.2, 1.5)
        drive(pair, 0.0, 1.5)
    per_second = commanded_return_pace(pair)
    assert per_second.max() >= 1.0, f"came back at {per_second.max():.2f} m/s on a stretch driven at 1.2"
    assert per_second.max() <= 1.2 * 1.1  # not faster than it was driven


class Scrambled:
    """A radio with 0 % loss in front of the vehicle's endpoint: "reorder" swaps two frames in every five (40 % out
    of order), "duplicate" delivers every frame a second time, after the next one."""

    def __init__(self, receive, mode: str) -> None:
        self.receive = receive
        self.mode = mode
        self.held: bytes | None = None
        self.n = 0

    def __call__(self, data: bytes, t: float) -> None:
        self.n += 1
        if self.mode == "reorder":
            if self.n % 5 == 0 and self.held is None:
                self.held = data
                return
            self.receive(data, t)
        else:
            self.receive(data, t)
        if self.held is not None:
            self.receive(self.held, t)
        self.held = data if self.mode == "duplicate" else None


@pytest.mark.parametrize("mode", ["reorder", "duplicate"])
def test_reordered_or_duplicated_frames_still_make_link_good_crumbs(mode):
    """Rule 3: the delivery estimate is not fooled by reordering or duplicates; with every packet arriving, the
    trail is link-good up to the loss and the return target is the last stretch driven, not the start."""
    pair = acquired(Pair())
    v = pair.vehicle
    pair.endpoint.receive = Scrambled(pair.endpoint.receive, mode)
    drive(pair, 1.0, 15.0)
    assert v.control.link_is_good
    x_loss = pair.driver.pose[0]
    t_loss = pair.t
    pair.lose = lambda sysid, t: True
    pair.until(lambda: any(r is ExpireReason.COMMS_LOST for _, r in reasons(pair, t_loss)), 5, "COMMS_LOST")
    pair.step(0.1)
    target = v.returns.service.route.target
    assert target is not None and x_loss - target[0] <= 3.0, (x_loss, target)
