"""Breadcrumb trail invariants (DESIGN §6) on random walks with loops, and the return planner on the patent's
FIG. 4A-4C situations."""

from __future__ import annotations

import math

import numpy as np
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
