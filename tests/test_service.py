"""The auto-return service driving a simulated robot: blocks complete, give up or get stuck as docs/architecture.md §6
says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim import scenario
from sim.drive import Rig
from vehicle.lease import ExpireReason
from vehicle.params import Params
from vehicle.service import (
    LEASE_BOUNDARY,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_RETURN_TO_LINK,
    NAV_WAYPOINT,
    PlanItem,
    blocks_from_items,
    default_plan,
    displacement,
    start,
    step,
)


def run_block(rig, block, params, link_lost=True, limit=600.0, watch=None):
    """Drive one block to its end; ``link_lost`` may be a function of the rig (the link coming back), and
    ``watch(rig, result)`` sees every step."""
    lost = link_lost if callable(link_lost) else (lambda _rig: link_lost)
    p = rig.estimator.pose
    res = start(block, p.x, p.y, rig.t, rig.trail, params, lost(rig), 1.2)
    max_disp = 0.0
    end = rig.t + limit
    while res.finished is None and rig.t < end:
        p = rig.estimator.pose
        res = step(res.state, p.x, p.y, p.yaw, rig.t, rig.trail, params, lost(rig), 1.2,
                   slipping=rig.estimator.slipping)
        rig.step(res.speed, res.yaw_rate)
        q = rig.estimator.pose
        max_disp = max(max_disp, displacement(res.state, q.x, q.y))
        if watch is not None:
            watch(rig, res)
    return res, max_disp


def outbound(name="tunnel", vehicle="rover"):
    s = scenario.load(name)
    rig = Rig(s, vehicle)
    gcs = s.stations[0]

    def los(x, y):
        return rig.world.attenuation_db((gcs.x, gcs.y), (x, y)) < 20.0

    assert rig.drive_route(link_good=los)
    return s, rig


def test_plan_splits_at_boundaries_and_rejects_unknown_items():
    params = Params()
    items = [PlanItem(NAV_RETURN_TO_LINK, 50), PlanItem(LEASE_BOUNDARY), PlanItem(NAV_LOITER_TIME, 60),
             PlanItem(LEASE_BOUNDARY), PlanItem(NAV_RETURN_TO_LAUNCH)]
    blocks = blocks_from_items(items, params)
    assert [b.payload[0].command for b in blocks] == [NAV_RETURN_TO_LINK, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH]
    assert blocks[0].halt_on_regain
    assert not blocks_from_items([PlanItem(NAV_RETURN_TO_LINK, param4=1)], params)[0].halt_on_regain
    with pytest.raises(ValueError, match="item 0"):  # a takeoff item has no place in a return plan
        blocks_from_items([PlanItem(22)], params)


def _dist(rig, target) -> float:
    p = rig.estimator.pose
    return math.hypot(p.x - target[0], p.y - target[1])


def test_return_to_link_passes_the_last_good_crumb_and_goes_on_while_the_link_stays_down():
    """docs/architecture.md §6: a RETURN_TO_LINK block that reaches its target without the link being back keeps going
    back along the trail, within its displacement budget (here the link never comes back)."""
    s, rig = outbound()
    good = rig.trail.link_good()
    target = rig.trail.points()[int(np.flatnonzero(good)[-1])]
    closest = [math.inf]
    res, max_disp = run_block(rig, default_plan(Params())[0], Params(),
                              watch=lambda r, _res: closest.__setitem__(0, min(closest[0], _dist(r, target))))
    assert closest[0] <= Params()["RTL_ARRIVE_R"] + 0.5  # it got to the target ...
    assert res.finished is ExpireReason.COMPLETED
    assert res.state.onward  # ... and went on
    budget = Params()["RTL_MAX_DISP"]
    assert budget - 1.5 <= max_disp <= budget + 0.3  # to the edge of its displacement budget
    assert rig.world.collisions == 0


def test_going_on_past_a_dead_zone_target_ends_when_the_link_is_back():
    s, rig = outbound()
    good = rig.trail.link_good()
    target = rig.trail.points()[int(np.flatnonzero(good)[-1])]
    params = Params()
    block = blocks_from_items([PlanItem(NAV_RETURN_TO_LINK, param4=1)], params)[0]  # continue on regain

    def lost(r):  # the link is back 5 m past the target (closer to the portal)
        return r.estimator.pose.x > target[0] - 5.0

    res, _ = run_block(rig, block, params, link_lost=lost)
    assert res.finished is ExpireReason.COMPLETED and res.state.onward
    assert target[0] - 7.0 <= rig.estimator.pose.x <= target[0] - 4.0


def test_return_never_exceeds_max_displacement():
    s, rig = outbound()
    params = Params()
    block = blocks_from_items([PlanItem(NAV_RETURN_TO_LINK, 8.0)], params)[0]
    res, max_disp = run_block(rig, block, params)
    assert res.finished is ExpireReason.COMPLETED
    assert max_disp <= 8.0 + 0.3  # stopped on the boundary (FIG. 4C), within the arrival tolerance


def test_fallback_chain_loiter_then_retrace_home():
    s, rig = outbound("loop")
    params = Params()
    loiter, home = blocks_from_items([PlanItem(NAV_LOITER_TIME, 5.0), PlanItem(LEASE_BOUNDARY),
                                      PlanItem(NAV_RETURN_TO_LAUNCH)], params)
    t0 = rig.t
    res, disp = run_block(rig, loiter, params)
    # holding: only braking from the outbound speed and fix noise move the estimate
    assert res.finished is ExpireReason.COMPLETED and 5.0 <= rig.t - t0 < 5.2 and disp < 0.5
    res, _ = run_block(rig, home, params)
    assert res.finished is ExpireReason.COMPLETED
    x, y, _ = rig.robot.pose
    assert math.hypot(x - s.start[0], y - s.start[1]) < 2.0


def test_timeout_and_stuck():
    s, rig = outbound()
    params = Params()
    params.set("RTL_MAX_TIME", 5.0)
    res, _ = run_block(rig, default_plan(params)[0], params)
    assert res.finished is ExpireReason.TIMEOUT



@pytest.mark.parametrize("vehicle", ["rover", "legged"])
def test_stuck_against_a_wall(vehicle):
    """A waypoint straight through the end of the drift: the robot presses against the rock. The rover's wheels
    spin and the quadruped's feet slip, so odometry reports the commanded motion; the estimator sees it disagree
    with the accelerometer, keeps the estimate where the robot is, and the block ends STUCK instead of arriving
    at an estimated target the robot never reached."""
    s, rig = outbound(vehicle=vehicle)
    params = Params()
    block = blocks_from_items([PlanItem(16, x=61.2, y=21.2)], params)[0]
    res, _ = run_block(rig, block, params, limit=120.0)
    assert res.finished is ExpireReason.STUCK
    assert rig.world.collisions >= 1  # it did reach the rock
    x, y, _ = rig.robot.pose
    p = rig.estimator.pose
    assert math.hypot(p.x - x, p.y - y) < 2.5  # the spinning did not carry the estimate off
    assert math.hypot(p.x - 61.2, p.y - 21.2) > 2.0  # and it is not "there"


def test_blocks_refuse_an_item_the_service_could_not_run():
    params = Params()
    for bad in (PlanItem(NAV_RETURN_TO_LINK, 50, 0, 7), PlanItem(NAV_RETURN_TO_LINK, -1),
                PlanItem(NAV_LOITER_TIME, float("nan")), PlanItem(NAV_WAYPOINT, x=float("inf"))):
        with pytest.raises(ValueError, match="item 0: "):
            blocks_from_items([bad], params)


def test_a_block_drives_its_route_from_the_tick_it_plans_it():
    """``start`` with the robot's heading, and an item begun mid-block, command the route's first step in the
    tick the route is planned: the tick a block waited cost it 20 ms against a baseline that drives at once.
    Without a heading (a caller that has none) the tick is a stop, as before."""
    s, rig = outbound()
    params = Params()
    p = rig.estimator.pose
    block = blocks_from_items([PlanItem(NAV_RETURN_TO_LINK, 50)], params)[0]
    res = start(block, p.x, p.y, rig.t, rig.trail, params, True, 1.2, yaw=p.yaw)
    assert res.replanned and res.finished is None
    assert res.speed != 0.0, "a planned route is driven from its first tick"
    assert res.state.progress >= 0.0 and res.state.best_remaining < math.inf
    still = start(block, p.x, p.y, rig.t, rig.trail, params, True, 1.2)
    assert still.replanned and (still.speed, still.yaw_rate) == (0.0, 0.0)
    # an item after a loiter: the tick the loiter ends plans the route and drives it
    block = blocks_from_items([PlanItem(NAV_LOITER_TIME, 0.1), PlanItem(NAV_RETURN_TO_LINK, 50)], params)[0]
    res = start(block, p.x, p.y, rig.t, rig.trail, params, True, 1.2, yaw=p.yaw)
    assert (res.speed, res.yaw_rate) == (0.0, 0.0)  # loitering
    res = step(res.state, p.x, p.y, p.yaw, rig.t + 0.2, rig.trail, params, True, 1.2)
    assert res.replanned and res.state.item == 1 and res.speed != 0.0
