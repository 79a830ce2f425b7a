"""Free space from a range sensor and the corners it lets a return cut (vehicle/clearance.py), and the simulated
sensor's beams (sim/world.py ``ranges``)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from sim.world import Wall, World
from vehicle.clearance import CELL, FREE, OCCUPIED, FreeSpace, shortcut
from vehicle.io import Scan

BEARINGS = np.arange(90) * (2 * math.pi / 90)  # the simulated sensor's
REACH = 8.0


def _room(inner: tuple[tuple[float, float], tuple[float, float]] | None = None) -> World:
    """A 10 x 10 m room (x north 0..10, y east 0..10), with an optional inner wall."""
    walls = [Wall(((0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0), (0.0, 0.0)), 0.2)]
    if inner is not None:
        walls.append(Wall(inner, 0.2))
    return World(tuple(walls))


def _scanned(world: World, poses: list[tuple[float, float]]) -> FreeSpace:
    free = FreeSpace()
    for x, y in poses:
        free.scan(x, y, 0.0, Scan(BEARINGS, world.ranges(x, y, BEARINGS, REACH), REACH))
    return free


def _wall_distance(world: World, a: np.ndarray, b: np.ndarray) -> float:
    """The least distance from segment a-b to any wall's surface (its centre line less half its thickness)."""
    best = math.inf
    for wall in world.walls:
        for p, q in zip(wall.points[:-1], wall.points[1:], strict=True):
            for s in np.linspace(0.0, 1.0, 41):
                c = np.asarray(a) + s * (np.asarray(b) - np.asarray(a))
                pq = np.subtract(q, p)
                u = min(1.0, max(0.0, float(np.dot(c - p, pq) / np.dot(pq, pq))))
                best = min(best, float(np.hypot(*(c - (np.asarray(p) + u * pq)))) - wall.thickness / 2)
    return best


def test_a_beam_stops_at_the_walls_face_and_a_beam_past_its_end_reaches_on():
    world = _room(((5.0, 0.0), (5.0, 6.0)))  # a wall across x = 5 from the west wall to y = 6
    r = world.ranges(2.0, 3.0, np.array([0.0, math.pi / 2, math.pi]), REACH)
    assert abs(r[0] - (5.0 - 0.1 - 2.0)) < 1e-9  # north, onto the inner wall's face
    assert abs(r[1] - (10.0 - 0.1 - 3.0)) < 1e-9  # east, the room's wall
    assert abs(r[2] - (2.0 - 0.1)) < 1e-9  # south
    # past the inner wall's end, 0.5 m east of it: beyond its round end (radius 0.1), the beam goes on
    far = world.ranges(2.0, 6.5, np.array([0.0]), REACH)
    assert abs(far[0] - (10.0 - 0.1 - 2.0)) < 1e-9
    # just inside the end's radius the end stops it
    cap = world.ranges(2.0, 6.05, np.array([0.0]), REACH)
    assert cap[0] < 3.1
    assert math.isinf(_room().ranges(5.0, 5.0, np.array([0.0]), 2.0)[0])  # nothing within reach


def test_seen_free_space_is_clear_and_a_wall_or_the_unseen_is_not():
    world = _room()
    free = _scanned(world, [(5.0, 5.0)])
    assert free.clear(np.array([4.0, 4.0]), np.array([6.0, 6.0]), 0.9)
    assert not free.clear(np.array([2.0, 2.0]), np.array([8.0, 8.0]), 0.9)  # out where the beams part: not seen
    assert not free.clear(np.array([0.8, 5.0]), np.array([0.8, 8.0]), 0.9)  # within 0.9 m of the west wall
    assert not free.clear(np.array([5.0, 5.0]), np.array([15.0, 5.0]), 0.5)  # beyond the wall: never seen
    assert not free.clear(np.array([5.0, 5.0]), np.array([6.0, 5.0]), 0.0)  # no clearance asked: no cut
    assert not free.clear(np.array([math.nan, 5.0]), np.array([6.0, 5.0]), 0.5)


def test_free_space_reaches_only_as_far_as_the_beams_are_a_cell_apart():
    # 90 beams are 4 degrees apart: a cell apart 3.58 m out. Further out a wall's end could hide between two beams,
    # so nothing there is booked free, though every beam ran on to 8 m
    free = FreeSpace()
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, np.full(90, math.inf), REACH))
    far = CELL / (2 * math.pi / 90) + CELL * math.sqrt(2)
    ix, iy, bits = free.seen()
    assert np.all(bits == FREE)
    assert np.hypot((ix + 0.5) * CELL, (iy + 0.5) * CELL).max() <= far
    assert len(ix) > 500  # and the near ring is booked


def test_a_cell_once_seen_occupied_stays_occupied():
    free = FreeSpace()
    # an obstacle 2 m north, then (it walked away) nothing there: the cell it was seen in stays occupied
    seen = np.full(90, math.inf)
    seen[0] = 2.0
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, seen, REACH))
    assert not free.clear(np.array([1.5, 0.0]), np.array([2.5, 0.0]), 0.1)
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, np.full(90, math.inf), REACH))
    assert int(np.count_nonzero(free.seen()[2] & OCCUPIED)) == 1
    assert not free.clear(np.array([1.5, 0.0]), np.array([2.5, 0.0]), 0.1)
    assert free.clear(np.array([0.0, 1.5]), np.array([0.0, 2.5]), 0.1)  # the same distance east: free


def test_bad_scans_are_skipped_not_trusted():
    free = FreeSpace()
    free.scan(math.nan, 0.0, 0.0, Scan(BEARINGS, np.full(90, 3.0), REACH))
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, np.full(89, 3.0), REACH))  # one range short
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, np.full(90, 3.0), -1.0))
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, np.full(90, 3.0), math.inf))
    free.scan(1e12, 0.0, 0.0, Scan(BEARINGS, np.full(90, 3.0), REACH))
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, ["far"] * 90, REACH))  # a driver's garbage: dropped, not raised
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, np.full(90, 3.0), None))
    assert free.cells == 0 and free.scans == 0
    # a NaN range or bearing drops that beam only
    r = np.full(90, 3.0)
    r[5] = math.nan
    free.scan(0.0, 0.0, 0.0, Scan(BEARINGS, r, REACH))
    assert free.scans == 1 and len(free.seen()[0]) > 100


def test_memory_is_bounded_and_forgetting_only_forbids_cuts():
    free = FreeSpace(max_cells=8192)  # eight tiles
    world = _room()
    free.scan(5.0, 5.0, 0.0, Scan(BEARINGS, world.ranges(5.0, 5.0, BEARINGS, REACH), REACH))
    a, b = np.array([4.0, 4.0]), np.array([6.0, 6.0])
    assert free.clear(a, b, 0.9)
    # open ground far away fills the memory: the room, seen first, is forgotten, and unseen means no cut
    for x in range(100, 200, 5):
        free.scan(float(x), 0.0, 0.0, Scan(BEARINGS, np.full(90, math.inf), REACH))
        assert free.cells <= 8192
    assert not free.clear(a, b, 0.9)


def _l_route() -> tuple[np.ndarray, np.ndarray]:
    """An L along the crumbs: north from (2, 2) to (8, 2), then east to (8, 8)."""
    pts = [(2.0 + k * 0.5, 2.0) for k in range(13)] + [(8.0, 2.5 + k * 0.5) for k in range(12)]
    return np.array(pts), np.full(len(pts), 0.8)


def test_an_open_rooms_corner_is_cut_and_the_cut_is_shorter_and_keeps_the_ends():
    world = _room()
    pts, sp = _l_route()
    free = _scanned(world, [tuple(p) for p in pts[::4]])
    cut, cut_sp = shortcut(pts, sp, free, 0.9)
    length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
    cut_length = float(np.hypot(*np.diff(cut, axis=0).T).sum())
    assert len(cut) < 5 and cut_length < length - 2.0
    assert np.array_equal(cut[0], pts[0]) and np.array_equal(cut[-1], pts[-1])
    assert len(cut_sp) == len(cut) and np.all(cut_sp == 0.8)
    # no clearance asked, no range sensor: the crumbs as they were
    assert shortcut(pts, sp, free, 0.0)[0] is pts and shortcut(pts, sp, None, 0.9)[0] is pts


def test_a_wall_inside_the_corner_is_not_cut_through():
    # an inner wall fills the L's inside from (4, 4) to (10, 4)... the cut must go round it, not across
    world = _room(((4.0, 4.0), (7.0, 4.0)))
    pts, sp = _l_route()
    free = _scanned(world, [tuple(p) for p in pts[::4]])
    cut, _ = shortcut(pts, sp, free, 0.9)
    for a, b in zip(cut[:-1], cut[1:], strict=True):
        assert _wall_distance(world, a, b) >= 0.9 - CELL * math.sqrt(2)


@given(wx=st.floats(3.0, 7.0), wy=st.floats(3.0, 7.0), length=st.floats(0.5, 4.0), angle=st.floats(0, math.pi),
       radius=st.floats(0.5, 1.5))
def test_no_cut_comes_closer_to_a_wall_than_the_clearance_less_a_cells_diagonal(wx, wy, length, angle, radius):
    """Whatever stands in the room, scanned from the crumbs the robot drove: every cut keeps its clearance, short
    of the grid's own resolution (a wall's cell may be seen free by a beam that grazed it)."""
    inner = ((wx, wy), (wx + length * math.cos(angle), wy + length * math.sin(angle)))
    world = _room(inner)
    pts, sp = _l_route()
    # the robot drove the crumbs, so none lies in the wall: drop the case where the wall crosses the route
    if min(_wall_distance(world, a, b) for a, b in zip(pts[:-1], pts[1:], strict=True)) < 0.5:
        return
    free = _scanned(world, [tuple(p) for p in pts[::2]])
    cut, _ = shortcut(pts, sp, free, radius)
    for a, b in zip(cut[:-1], cut[1:], strict=True):
        if np.allclose(a, b):
            continue
        # a segment that is one of the crumbs' own stretches is where the robot drove: not a cut
        if any(np.allclose(a, p) and np.allclose(b, q) for p, q in zip(pts[:-1], pts[1:], strict=True)):
            continue
        assert _wall_distance(world, a, b) >= radius - CELL * math.sqrt(2)
