"""Breadcrumb trail invariants (docs/architecture.md §6) on random walks with loops, and the return planner on the
patent's FIG. 4A-4C situations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vehicle.returning import Target, plan_route, polyline_length, target_index
from vehicle.trail import Crumb, Trail, TrailConfig


def seg_dist(p, a, b):
    ab = b - a
    L2 = float(ab @ ab)
    if L2 == 0:
        return float(np.hypot(*(p - a)))
    u = min(1, max(0, float((p - a) @ ab) / L2))
    return float(np.hypot(*(p - a - u * ab)))


def poly_dist(p, pts):
    if len(pts) == 1:
        return float(np.hypot(*(p - pts[0])))
    return min(seg_dist(p, pts[k], pts[k + 1]) for k in range(len(pts) - 1))


@st.composite
def walks(draw, max_len=400):
    """A random drive: straight runs, turns, the odd full circle (a loop), link lost and regained."""
    n = draw(st.integers(20, max_len))
    turns = draw(st.lists(st.floats(-0.5, 0.5), min_size=n, max_size=n))
    circles = draw(st.lists(st.integers(0, n - 1), max_size=3))
    loss_at = draw(st.integers(0, n))
    back_at = draw(st.integers(loss_at, n + 50))
    x = y = yaw = 0.0
    out = []
    for k in range(n):
        yaw += turns[k] * 0.3
        if k in circles:
            yaw += 2 * math.pi / 25  # a circle of 25 steps comes back on itself: a loop
            for _ in range(25):
                yaw += 2 * math.pi / 25
                x += 0.3 * math.cos(yaw)
                y += 0.3 * math.sin(yaw)
                out.append((x, y, not (loss_at <= len(out) < back_at)))
        x += 0.3 * math.cos(yaw)
        y += 0.3 * math.sin(yaw)
        out.append((x, y, not (loss_at <= len(out) < back_at)))
    return out


def feed(walk, cfg):
    trail = Trail(cfg)
    crumbs = []
    for k, (x, y, good) in enumerate(walk):
        c = Crumb(x, y, 0.1 * k, 0.1, good)
        trail.add(c)
        crumbs.append(c)
    return trail, crumbs


@settings(max_examples=150, deadline=None)
@given(walks(), st.sampled_from([0.05, 0.25, 1.0]))
def test_every_crumb_stays_within_tolerance_of_the_kept_trail(walk, tol):
    trail, crumbs = feed(walk, TrailConfig(spacing=0.25, tolerance=tol, loop_distance=1.0, max_points=5000))
    pts = trail.points()
    for c in crumbs:
        assert poly_dist(np.array([c.x, c.y]), pts) <= max(tol, 0.25) + 1e-6


@settings(max_examples=150, deadline=None)
@given(walks(), st.booleans())
def test_target_from_compressed_trail_equals_full_trail(walk, lost):
    trail, crumbs = feed(walk, TrailConfig(spacing=0.25, tolerance=0.25, max_points=5000))
    full_good = np.array([c.link_good for c in crumbs])
    full_pts = np.array([[c.x, c.y] for c in crumbs])
    i_full = target_index(full_good, Target.LINK, lost)
    i_comp = target_index(trail.link_good(), Target.LINK, lost)
    assert np.allclose(full_pts[i_full], trail.points()[i_comp])


@settings(max_examples=60, deadline=None)
@given(walks(max_len=1500), st.integers(50, 120))
def test_memory_is_bounded_and_the_trail_never_deactivates(walk, cap):
    trail, crumbs = feed(walk, TrailConfig(spacing=0.1, tolerance=0.05, max_points=cap))
    assert trail.count <= cap
    assert len(trail) >= 2
    # degraded tolerances grow from the oldest part: every crumb is still within its part's tolerance
    pts = trail.points()
    assert poly_dist(np.array([crumbs[-1].x, crumbs[-1].y]), pts) < 1e-9
    assert trail.max_tolerance >= 0.05
    # the newest part keeps the configured tolerance
    assert trail.tolerances()[-1] == 0.05


def test_link_transitions_are_anchors():
    trail = Trail(TrailConfig(spacing=0.1, tolerance=1.0))
    for k in range(100):
        trail.add(Crumb(0.2 * k, 0.0, k, link_good=k < 60))
    pts, good = trail.points(), trail.link_good()
    # a straight line would be two points; the link transition keeps both of its sides
    i = int(np.flatnonzero(good)[-1])
    assert math.isclose(pts[i, 0], 0.2 * 59) and math.isclose(pts[i + 1, 0], 0.2 * 60)
    assert len(pts) == 4


def square_loop_drive():
    """Out along x, a 6 m square loop that crosses its own path, then on: FIG. 4B."""
    path = [(0.25 * k, 0.0) for k in range(41)]  # to (10, 0)
    path += [(10 + 0.25 * k, 0.0) for k in range(1, 25)]  # to (16, 0)
    path += [(16.0, 0.25 * k) for k in range(1, 25)]  # up to (16, 6)
    path += [(16 - 0.25 * k, 6.0) for k in range(1, 25)]  # left to (10, 6)
    path += [(10.0, 6 - 0.25 * k) for k in range(1, 41)]  # down through (10, 0) to (10, -4)
    return path


def test_fig4a_return_target_is_where_the_link_was_last_good():
    trail = Trail(TrailConfig(spacing=0.2, tolerance=0.1))
    for k in range(200):
        trail.add(Crumb(0.25 * k, 0.0, k, link_good=k < 120))
    route = plan_route(trail, (49.75, 0.0), Target.LINK, max_displacement=100.0, link_lost=True)
    assert not route.truncated
    assert math.isclose(route.end[0], 0.25 * 119, abs_tol=1e-9)
    # an operator-commanded return (no loss) goes back to the trail's start, still bounded
    route2 = plan_route(trail, (49.75, 0.0), Target.LINK, max_displacement=100.0, link_lost=False)
    assert route2.end == (0.0, 0.0)


def test_fig4b_loops_are_pruned_from_the_route():
    trail = Trail(TrailConfig(spacing=0.2, tolerance=0.1, loop_distance=1.0))
    for k, (x, y) in enumerate(square_loop_drive()):
        trail.add(Crumb(x, y, k, link_good=x < 5))
    route = plan_route(trail, (10.0, -4.0), Target.LINK, max_displacement=100.0, link_lost=True)
    driven = 4 + 6 + 6 + 6 + 6 + 5  # back along every metre, loop included
    assert route.length < driven - 20  # the 24 m loop is skipped
    assert route.length < 12.0
    assert route.end[0] < 5.0


def test_fig4c_route_stops_on_the_displacement_boundary():
    trail = Trail(TrailConfig(spacing=0.2, tolerance=0.1))
    for k in range(400):
        trail.add(Crumb(0.25 * k, 0.0, k, link_good=k < 20))
    start = (0.25 * 399, 0.0)
    route = plan_route(trail, start, Target.LINK, max_displacement=30.0, link_lost=True)
    assert route.truncated
    assert math.isclose(math.hypot(route.end[0] - start[0], route.end[1] - start[1]), 30.0, rel_tol=1e-9)
    assert route.target is not None and route.target[0] < route.end[0]
    assert polyline_length(route.points) <= 30.0 + 1e-9


def test_heading_target_drives_a_bearing():
    trail = Trail()
    trail.add(Crumb(0, 0, 0))
    route = plan_route(trail, (1.0, 1.0), Target.HEADING, 20.0, link_lost=True, heading=math.pi / 2)
    assert np.allclose(route.end, (1.0, 21.0))


def test_update_cost_is_bounded_work():
    """Amortised O(1): the number of compactions grows like n / capacity, not faster."""
    trail = Trail(TrailConfig(spacing=0.1, tolerance=0.01, max_points=100))
    rng = np.random.default_rng(1)
    x = y = yaw = 0.0
    for k in range(20000):
        yaw += rng.normal(0, 0.4)
        x += 0.2 * math.cos(yaw)
        y += 0.2 * math.sin(yaw)
        trail.add(Crumb(x, y, k))
    assert trail.count <= 100
    # each compaction frees >= an eighth of the memory, so there are at most n / (cap / 8) of them
    assert 0 < trail.compactions <= 20000 // 12


def fold_drive(back_to: float, then_up: float = 0.0):
    """Out along x to (10, 0), straight back along x to (back_to, 0) (the robot backs up over its own track), then
    ``then_up`` metres off at a right angle."""
    path = [(0.25 * k, 0.0) for k in range(41)]
    path += [(10 - 0.25 * k, 0.0) for k in range(1, int(round((10 - back_to) / 0.25)) + 1)]
    path += [(back_to, 0.25 * k) for k in range(1, int(round(then_up / 0.25)) + 1)]
    return path


@pytest.mark.parametrize("back_to", [9.0, 7.5, 4.0])
def test_an_exact_fold_back_is_a_loop_of_zero_width(back_to):
    """Back along x over the outbound track: a route from there must not first drive out to the turn point."""
    trail = Trail(TrailConfig(spacing=0.2, tolerance=0.1, loop_distance=1.0))
    for k, (x, y) in enumerate(fold_drive(back_to)):
        trail.add(Crumb(x, y, k))
    route = plan_route(trail, (back_to, 0.0), Target.ORIGIN, max_displacement=100.0, link_lost=False)
    assert route.end == (0.0, 0.0)
    assert route.points[:, 0].max() <= back_to + 0.1 + 1e-9
    assert route.length <= back_to + 0.2
    # nothing was dropped to do it: the turn point is still on the trail
    assert np.isclose(trail.points()[:, 0].max(), 10.0)


def test_a_partial_fold_back_is_cut_and_the_leg_off_it_kept():
    """Back along the last segment to x = 8 (less than the 3 TRL_LOOP_D of path an ordinary loop needs), then 5 m
    off at a right angle: the route comes down the side leg and joins the outbound track at x = 8, without the
    4 m there and back to the turn point."""
    trail = Trail(TrailConfig(spacing=0.2, tolerance=0.1, loop_distance=1.0))
    for k, (x, y) in enumerate(fold_drive(8.0, then_up=5.0)):
        trail.add(Crumb(x, y, k))
    route = plan_route(trail, (8.0, 5.0), Target.ORIGIN, max_displacement=100.0, link_lost=False)
    assert route.end == (0.0, 0.0)
    assert route.points[:, 0].max() <= 8.0 + 0.1 + 1e-9
    assert route.length <= 5.0 + 8.0 + 0.2
    # the side leg itself is driven back, not cut across: the route passes within the tolerance of (8, 2.5)
    assert poly_dist(np.array([8.0, 2.5]), route.points) <= 0.1 + 1e-9


def test_a_fold_back_keeps_the_return_target_and_the_tags_of_its_own_crumbs():
    """Out with the link good, a commanded return backs up over the track (its own crumbs tagged good, as they
    were), then the link dies: the target is the last good crumb, on the folded part, and the way on from it
    (a dead zone) leads toward the start, not out to the turn point (docs/architecture.md §6)."""
    trail = Trail(TrailConfig(spacing=0.2, tolerance=0.1, loop_distance=1.0))
    walk = fold_drive(7.0)
    walk += [(7.0 - 0.25 * k, 0.0) for k in range(1, 3)]  # on back, the link now lost
    crumbs = [Crumb(x, y, k, link_good=k < len(walk) - 2) for k, (x, y) in enumerate(walk)]
    for c in crumbs:
        trail.add(c)
    i_full = target_index(np.array([c.link_good for c in crumbs]), Target.LINK, True)
    i_comp = target_index(trail.link_good(), Target.LINK, True)
    assert np.allclose(trail.points()[i_comp], (crumbs[i_full].x, crumbs[i_full].y))
    route = plan_route(trail, (6.5, 0.0), Target.LINK, max_displacement=100.0, link_lost=True, overshoot=2.0)
    assert np.allclose(route.target, (7.0, 0.0))
    assert route.points[:, 0].max() <= 7.0 + 0.1 + 1e-9
    assert route.onward is not None and route.onward.end == (0.0, 0.0)
    assert route.onward.points[:, 0].max() <= 7.0 + 0.1 + 1e-9


@pytest.mark.parametrize("turn_deg", [0.0, 90.0, 120.0, 135.0])
def test_ordinary_turns_and_link_transitions_are_not_folds(turn_deg):
    """Only a stretch heading back along the previous one is cut: a corner, even a sharp one, and the two sides of
    a link transition (a segment too short to have a direction) leave the route as driven."""
    trail = Trail(TrailConfig(spacing=0.2, tolerance=0.1, loop_distance=1.0))
    a = math.radians(turn_deg)
    walk = [(1e-6, 0.0, False)]  # at rest when the link came: both sides of the transition at one spot
    walk += [(0.25 * k, 0.0, not 20 <= k < 30) for k in range(41)]
    walk += [(10 + 0.25 * k * math.cos(a), 0.25 * k * math.sin(a), True) for k in range(1, 25)]
    for k, (x, y, good) in enumerate(walk):
        trail.add(Crumb(x, y, k, link_good=good))
    assert all(trail.shortcut(i) == -1 for i in range(len(trail)))



def test_a_stretch_keeps_the_fastest_speed_driven_on_it_through_simplification_and_compaction():
    """The pace a return copies (RTL_SPEED=0) is the fastest the robot went on a stretch, not its length over its
    time, and a stretch that compaction merges is as fast as the fastest part of it."""
    trail = Trail(TrailConfig(spacing=0.5, tolerance=0.25, max_points=50))
    speeds = {}
    for k in range(200):  # a zig-zag wider than the tolerance: every crumb is kept until memory runs out
        x, y = 0.5 * k, 0.3 * (k % 2)
        speeds[x] = 1.8 if k % 7 == 3 else 0.9
        trail.add(Crumb(x, y, 1.0 * k, 0.1, True, math.nan, speeds[x]))
    assert trail.compactions > 0
    xs, pace = trail.points()[:, 0], trail.paces()
    merged = 0
    for a, b, p in zip(xs[:-1], xs[1:], pace[1:], strict=True):
        expect = max(v for x, v in speeds.items() if a < x <= b + 1e-9)
        assert p == pytest.approx(expect), (a, b)
        merged += b - a > 0.6
    assert merged > 0  # compaction did merge stretches
