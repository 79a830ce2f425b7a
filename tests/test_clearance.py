"""Free space from a range sensor and the corners it lets a return cut (vehicle/clearance.py), and the simulated
sensor's beams (sim/world.py ``ranges``)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from sim.world import Wall, World
from vehicle.clearance import (
    CELL,
    FREE,
    HOLD,
    OCCUPIED,
    TAPER,
    FreeSpace,
    _spread,
    keep_clear,
    shortcut,
)
from vehicle.io import Scan
from vehicle.returning import Target, heard_stretch, plan_route
from vehicle.trail import Crumb, Trail

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


def _l_trail(heard_to: float) -> Trail:
    """The L of ``_l_route`` driven as crumbs every 2 cm, north from (2, 2) to (8, 2) then east to (8, 8), the
    link heard up to ``heard_to`` metres east along the second leg and lost beyond."""
    trail = Trail()
    pts = [(2.0 + 0.02 * k, 2.0) for k in range(300)] + [(8.0, 2.0 + 0.02 * k) for k in range(301)]
    for k, (x, y) in enumerate(pts):
        trail.add(Crumb(x, y, 0.02 * k, 0.1, x < 8.0 or y <= 2.0 + heard_to, speed=0.8))
    return trail


def test_a_return_drives_the_stretch_the_link_was_last_heard_on_as_driven_and_cuts_corners_before_it():
    """After a loss the route may cut corners only up to where the last stretch driven with the link ended: the
    link comes back first along that stretch, and a cut past it leaves the known way to the link for an unknown
    one (gen:mine rover seed 124: 6.80 s to link against 5.40 s). Here the link was heard along the whole north
    leg and 1 m into the east one: the route cuts nothing past (8, 3) and so turns at the corner (8, 2) where the
    crumbs turned, though the room is open and seen free; without a loss (an operator's RTL) it cuts the corner."""
    world = _room()
    trail = _l_trail(1.0)
    free = _scanned(world, [(x, y) for x in (2.0, 4.0, 6.0, 8.0) for y in (2.0, 4.0, 6.0, 8.0)])
    lost = plan_route(trail, (8.0, 8.0), Target.LINK, 100.0, link_lost=True, overshoot=4.0, free=free,
                      clearance=0.9)
    assert np.min(np.hypot(*(lost.points - (8.0, 2.0)).T)) < 1e-6  # the corner crumb is on the route
    assert np.allclose(lost.points[-1], (5.0, 2.0), atol=0.05)  # 4 m on from the last heard crumb (8, 3)
    rtl = plan_route(trail, (8.0, 8.0), Target.ORIGIN, 100.0, link_lost=False, free=free, clearance=0.9)
    assert np.min(np.hypot(*(rtl.points - (8.0, 2.0)).T)) > 0.5  # nothing was lost: the corner is cut


def test_a_lone_packet_heard_in_a_dead_place_is_not_the_stretch_the_link_held_on():
    """``heard_stretch``: the newest link-good crumb whose predecessor was link-good too, at or before the goal."""
    assert heard_stretch(np.array([True, True, True, False, True, False, False]), 4) == 2
    assert heard_stretch(np.array([True, True, True, False, True, True, False]), 5) == 5
    assert heard_stretch(np.array([False, True, False, True, False]), 3) == -1
    assert heard_stretch(np.array([True, True, True]), 1) == 1  # never past the goal
    assert heard_stretch(np.array([], dtype=bool), 0) == -1


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


# -- keeping the route clear of what the sensor saw occupied (keep_clear) --

CLR = 0.9  # RTL_CUT_CLR's default


def _grid(seen: tuple[tuple[float, float], tuple[float, float]], occupied: list[tuple[float, float]],
          unseen: tuple[float, float] | None = None) -> FreeSpace:
    """A synthetic grid: every cell of the box ``seen`` ((x0, x1), (y0, y1)) seen free, but those of the band
    ``unseen`` (y0, y1) across it, which nobody saw; the cells of the points ``occupied`` seen occupied (only)."""
    free = FreeSpace()
    (x0, x1), (y0, y1) = seen
    ix, iy = np.meshgrid(np.arange(math.floor(x0 / CELL), math.ceil(x1 / CELL)),
                         np.arange(math.floor(y0 / CELL), math.ceil(y1 / CELL)), indexing="ij")
    occ = {(math.floor(x / CELL), math.floor(y / CELL)) for x, y in occupied}
    keep = np.array([(a, b) not in occ for a, b in zip(ix.ravel(), iy.ravel(), strict=True)])
    if unseen is not None:
        y = (iy.ravel() + 0.5) * CELL
        keep &= (y < unseen[0]) | (y >= unseen[1])
    free._book(ix.ravel()[keep], iy.ravel()[keep], FREE)
    if occ:
        cells = np.array(sorted(occ))
        free._book(cells[:, 0], cells[:, 1], OCCUPIED)
    return free


def _occupied(free: FreeSpace) -> np.ndarray:
    """Centres of the cells seen occupied."""
    ix, iy, bits = free.seen()
    sel = (bits & OCCUPIED) != 0
    return np.stack([(ix[sel] + 0.5) * CELL, (iy[sel] + 0.5) * CELL], axis=1)


def _clearance(points: np.ndarray, occ: np.ndarray) -> np.ndarray:
    """Per point, the distance to the nearest occupied cell's centre."""
    if len(occ) == 0:
        return np.full(len(points), math.inf)
    return np.hypot(points[:, None, 0] - occ[None, :, 0], points[:, None, 1] - occ[None, :, 1]).min(axis=1)


def _along(points: np.ndarray, step: float = 0.05) -> np.ndarray:
    """The polyline sampled every ``step`` metres or closer (its segments, not only its corners)."""
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:], strict=True):
        k = max(1, int(math.ceil(float(np.hypot(*(b - a))) / step)))
        out.append(a + np.linspace(0.0, 1.0, k + 1)[1:, None] * (b - a))
    return np.vstack(out)


# a straight route north along y = 0, crumbs every half metre; a wall 0.4 m east of it from x = 3 to 7 (the cells
# the sensor saw its face in), open space seen free everywhere else from y = -3 to 3
_STRAIGHT = np.array([(0.5 * k, 0.0) for k in range(21)])
_WALL = [(x, 0.4) for x in np.arange(3.0, 7.0, CELL)]


def test_a_route_past_a_wall_is_pushed_clear_of_it_and_keeps_its_ends():
    free = _grid(((-3.0, 13.0), (-3.0, 3.0)), _WALL)
    occ = _occupied(free)
    speeds = np.full(len(_STRAIGHT), 0.8)
    pts, sp = keep_clear(_STRAIGHT, speeds, free, CLR)
    assert np.array_equal(pts[0], _STRAIGHT[0]) and np.array_equal(pts[-1], _STRAIGHT[-1])
    assert _clearance(_STRAIGHT, occ).min() < 0.5  # the crumbs pass the wall at 0.4 m
    # every point of the route, between its corners too, keeps the clearance less a cell's diagonal
    assert _clearance(_along(pts), occ).min() >= CLR - CELL * math.sqrt(2)
    assert _clearance(pts, occ).min() >= CLR - 1e-9  # its corners keep the whole clearance
    assert pts[:, 1].max() <= 1e-9  # pushed west, away from the wall, not through it
    assert len(sp) == len(pts) and np.all(sp == 0.8)
    # the stretches far from the wall keep their crumbs: the route only bends where it has to
    assert np.all(np.abs(pts[pts[:, 0] <= 1.5, 1]) < 1e-9) and np.all(np.abs(pts[pts[:, 0] >= 8.5, 1]) < 1e-9)
    # the bend leans in and out, half a metre sideways per metre along at most
    d = np.diff(pts, axis=0)
    assert np.all(np.abs(d[:, 1]) <= 0.5 * np.abs(d[:, 0]) + 1e-9)


def test_a_route_pushed_off_a_wall_round_a_bend_turns_no_sharper_than_its_crumbs():
    """A drift's wall 0.5 m off the crumbs before a bend into a shaft, a doubled crumb at the bend (the robot
    paused there): the pushed route used to keep the bend's crumbs where they were between pushed neighbours, a
    134 degree zigzag of 0.5 m legs that the follower crawled through (gen:mine rover seed 132: 0.63 m/s back
    where it drove 1.2). A leg that would go backward now loses its moved end instead."""
    a, c, e = np.array([4.0, -3.0]), np.array([2.0, 0.0]), np.array([-2.0, 0.0])
    pts = np.array([a + (c - a) * t for t in np.linspace(0.0, 1.0, 9)] + [c + np.array([-0.01, 0.02])]
                   + [c + (e - c) * t for t in np.linspace(0.0, 1.0, 9)[1:]])
    n = np.array([3.0, 2.0]) / math.hypot(3.0, 2.0)
    wall = [tuple(a + (c - a) * t + 0.5 * n) for t in np.linspace(-0.2, 1.0, 30)]
    wall += [(x, 0.5) for x in np.arange(-2.0, 2.3, CELL)]
    free = _grid(((-4.0, 6.0), (-5.0, 3.0)), wall)
    out, sp = keep_clear(pts, np.full(len(pts), 1.2), free, CLR)
    assert len(out) > 2 and len(sp) == len(out)

    def sharpest(p: np.ndarray) -> float:
        heading = np.arctan2(*np.diff(p, axis=0)[:, ::-1].T)
        return float(np.abs((np.diff(heading) + math.pi) % (2 * math.pi) - math.pi).max())

    assert sharpest(out) <= sharpest(pts) + math.radians(30.0)
    occ = _occupied(free)
    assert _clearance(out[3:-3], occ).min() >= _clearance(pts[3:-3], occ).min() - 1e-9  # and it still moved off


def test_no_range_sensor_no_clearance_nothing_seen_keep_the_route_as_it_was():
    speeds = np.full(len(_STRAIGHT), 0.8)
    free = _grid(((-3.0, 13.0), (-3.0, 3.0)), _WALL)
    for grid, radius in ((None, CLR), (FreeSpace(), CLR), (free, 0.0)):
        pts, sp = keep_clear(_STRAIGHT, speeds, grid, radius)
        assert pts is _STRAIGHT and sp is speeds
    # nothing occupied near it: the very same route
    pts, sp = keep_clear(_STRAIGHT, speeds, _grid(((-3.0, 13.0), (-3.0, 3.0)), []), CLR)
    assert pts is _STRAIGHT and sp is speeds


def test_where_the_clearance_cannot_be_had_the_route_goes_as_far_from_the_walls_as_it_can_at_its_pace():
    # a corridor 1.2 m wide from x = 3 to 7: no point in it is 0.9 m from both walls. On its centre line already,
    # the route stays; driven along its west wall (the operator's clip), it is moved to the centre; neither is
    # slowed (measured: slowing there cost the culverts' returns seconds and kept none off a wall)
    walls = [(x, y) for x in np.arange(3.0, 7.0, CELL) for y in (0.6, -0.6)]
    free = _grid(((-3.0, 13.0), (-3.0, 3.0)), walls)
    speeds = np.full(len(_STRAIGHT), 1.2)
    pts, sp = keep_clear(_STRAIGHT, speeds, free, CLR)
    assert pts is _STRAIGHT and sp is speeds
    off = _STRAIGHT + np.array([0.0, -0.35])
    off[0], off[-1] = _STRAIGHT[0], _STRAIGHT[-1]
    pts, sp = keep_clear(off, speeds, free, CLR)
    mid = (pts[:, 0] > 3.5) & (pts[:, 0] < 6.5)
    occ = _occupied(free)
    assert np.all(np.abs(pts[mid, 1]) < 0.2)
    assert _clearance(pts[mid], occ).min() > _clearance(off[(off[:, 0] > 3.5) & (off[:, 0] < 6.5)], occ).max()
    assert len(sp) == len(pts) and np.all(sp == 1.2)


def test_a_point_is_never_moved_into_or_across_unseen_space():
    # the wall 0.4 m east, and nothing seen west of y = -0.25: the route moves as far as the seen cells go (a cell
    # from -0.25 to 0), not to the clearance, so it also slows down
    free = _grid(((-3.0, 13.0), (-0.25, 3.0)), _WALL)
    speeds = np.full(len(_STRAIGHT), 0.8)
    pts, _ = keep_clear(_STRAIGHT, speeds, free, CLR)
    assert -0.25 <= pts[:, 1].min() < -0.1
    # an unseen strip west of the route (y from -0.5 to -0.25) with free space beyond it: the route does not jump it
    free = _grid(((-3.0, 13.0), (-3.0, 3.0)), _WALL, unseen=(-0.5, -0.25))
    pts, _ = keep_clear(_STRAIGHT, speeds, free, CLR)
    assert pts[:, 1].min() >= -0.25
    assert keep_clear(_STRAIGHT, speeds, _grid(((-3.0, 13.0), (-3.0, 3.0)), _WALL), CLR)[0][:, 1].min() < -0.4


@given(x0=st.floats(1.5, 8.0), y0=st.floats(-1.5, 1.5), length=st.floats(0.25, 5.0), angle=st.floats(0, math.pi),
       bend=st.floats(-1.0, 1.0), hole=st.floats(-2.0, 2.0), radius=st.floats(0.4, 1.5))
def test_no_point_is_moved_closer_to_an_occupied_cell_or_onto_one_not_seen_free(x0, y0, length, angle, bend, hole,
                                                                                  radius):
    """Whatever was seen occupied near a route (a wall at any angle, even across it) and wherever the unseen is,
    each point ends no closer to an occupied cell than it was (beyond the clearance, distance is not wanted), on a
    cell seen free, moved no further than the clearance; the ends stay."""
    wall = [(x0 + t * math.cos(angle), y0 + t * math.sin(angle)) for t in np.arange(0.0, length, 0.5 * CELL)]
    free = _grid(((-3.0, 13.0), (-3.0, 3.0)), wall, unseen=(hole, hole + CELL))  # a band nobody saw
    occ = _occupied(free)
    # a bent route with segments under a cell long, so each of its points is one sample of the shift
    route = np.array([(0.2 * k, bend * math.sin(0.2 * k / 3.0)) for k in range(51)])
    pts, sp = keep_clear(route, np.full(len(route), 1.0), free, radius)
    assert len(pts) == len(route)
    assert np.array_equal(pts[0], route[0]) and np.array_equal(pts[-1], route[-1])
    before, after = _clearance(route, occ), _clearance(pts, occ)
    assert np.all(np.minimum(after, radius) >= np.minimum(before, radius) - 1e-9)
    moved = np.hypot(*(pts - route).T) > 1e-12
    assert np.all(np.hypot(*(pts - route).T) <= radius + 1e-9)
    cells = np.floor(pts[moved] / CELL).astype(np.int64)
    ix, iy, bits = free.seen()
    state = {(a, b): v for a, b, v in zip(ix.tolist(), iy.tolist(), bits.tolist(), strict=True)}
    assert all(state.get((a, b), 0) == FREE for a, b in cells.tolist())


def _trail_north(length: float) -> Trail:
    trail = Trail()
    for k in range(int(length / 0.02) + 1):
        x = 0.02 * k
        trail.add(Crumb(x, 0.0, 0.02 * k, 0.1, True, speed=1.0))
    return trail


def test_a_planned_return_keeps_clear_of_a_wall_its_crumbs_ran_close_to():
    """The whole planning step (vehicle/returning.py): the retraced route is pushed off the wall the sensor saw,
    its ends stay, and a robot without the sensor keeps the crumbs."""
    trail = _trail_north(10.0)
    free = _grid(((-3.0, 13.0), (-3.0, 3.0)), _WALL)
    occ = _occupied(free)
    route = plan_route(trail, (10.0, 0.0), Target.ORIGIN, 100.0, link_lost=False, free=free, clearance=CLR)
    assert np.allclose(route.points[0], (10.0, 0.0)) and np.allclose(route.points[-1], (0.0, 0.0))
    assert _clearance(_along(route.points), occ).min() >= CLR - CELL * math.sqrt(2)
    assert len(route.speeds) == len(route.points)
    blind = plan_route(trail, (10.0, 0.0), Target.ORIGIN, 100.0, link_lost=False, clearance=CLR)
    assert _clearance(_along(blind.points), occ).min() < 0.5


def test_the_way_on_past_a_dead_zone_target_keeps_clear_too():
    """After a loss the route carries ``onward``, the way beyond its target that the service drives when the target
    turns out to be a dead zone: it is kept clear of the wall like the route itself."""
    trail = Trail()
    for k in range(1001):  # north from 0 to 20 m; the link good up to 14 m
        x = 0.02 * k
        trail.add(Crumb(x, 0.0, 0.02 * k, 0.1, x <= 14.0, speed=1.0))
    free = _grid(((-3.0, 23.0), (-3.0, 3.0)), _WALL)
    occ = _occupied(free)
    route = plan_route(trail, (20.0, 0.0), Target.LINK, 100.0, link_lost=True, overshoot=1.0, free=free,
                       clearance=CLR)
    assert route.onward is not None and route.onward.points[:, 0].min() < 3.0  # it passes the wall
    assert _clearance(_along(route.onward.points), occ).min() >= CLR - CELL * math.sqrt(2)
    assert np.allclose(route.onward.points[-1], (0.0, 0.0))


def test_after_a_loss_the_way_to_where_the_link_was_last_heard_keeps_its_crumbs_and_is_kept_clear_beyond():
    """The operator drove the dead end (x 14 to 20, the link lost past 14) along a wall 0.4 m east: after a loss the
    route retraces those crumbs as driven, where the link will come back (pushed 0.5 m off them into the drift's
    radio shadow, gen:mine rover seed 203 took 6.40 s to link against back-up's 5.42; kept to them, 5.42), and is
    pushed off a second wall past the place the link was heard. An operator's RTL over a good link, which has no
    link to find, is pushed off both."""
    trail = Trail()
    for k in range(1001):  # north from 0 to 20 m; the link good up to 14 m
        x = 0.02 * k
        trail.add(Crumb(x, 0.0, 0.02 * k, 0.1, x <= 14.0, speed=1.0))
    dead_end = [(x, 0.4) for x in np.arange(16.0, 19.0, CELL)]
    beyond = [(x, 0.4) for x in np.arange(9.5, 12.0, CELL)]
    free = _grid(((-3.0, 23.0), (-3.0, 3.0)), dead_end + beyond)
    occ_dead, occ_beyond = _occupied(_grid(((0.0, 0.1), (0.0, 0.1)), dead_end)), _occupied(
        _grid(((0.0, 0.1), (0.0, 0.1)), beyond))
    lost = plan_route(trail, (20.0, 0.0), Target.LINK, 100.0, link_lost=True, overshoot=6.0, free=free,
                      clearance=CLR)
    heard_way = lost.points[lost.points[:, 0] >= 14.0 - 1e-9]
    assert np.all(np.abs(heard_way[:, 1]) < 1e-9)  # the crumbs, as driven
    assert _clearance(_along(heard_way), occ_dead).min() < 0.5
    assert lost.points[:, 0].min() < 9.0  # the route passes the second wall...
    assert _clearance(_along(lost.points), occ_beyond).min() >= CLR - CELL * math.sqrt(2)  # ...kept clear of it
    rtl = plan_route(trail, (20.0, 0.0), Target.ORIGIN, 100.0, link_lost=False, free=free, clearance=CLR)
    assert _clearance(_along(rtl.points), occ_dead).min() >= CLR - CELL * math.sqrt(2)
    assert _clearance(_along(rtl.points), occ_beyond).min() >= CLR - CELL * math.sqrt(2)


@given(st.lists(st.tuples(st.floats(0.01, 1.0), st.floats(0.0, 1.0)), min_size=1, max_size=40))
def test_the_lean_is_what_it_says(steps):
    """keep_clear's window pass against its definition, computed the slow way."""
    s = np.cumsum([a for a, _ in steps])
    move = np.array([b for _, b in steps])
    gap = np.abs(s[:, None] - s[None, :])
    want = (move[None, :] - TAPER * np.maximum(0.0, gap - HOLD)).max(axis=1)
    assert np.allclose(_spread(move, s), want)
