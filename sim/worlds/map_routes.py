"""Routes on an owner's map: from the station outward over the free space to a place where the link has died.

The operator of a map world drives as the generated worlds' operator does (``sim.worlds.build``): from the
station along a centre line, a few metres past where the mean link dies, with the same checks, redraws, plan and
criteria (docs/architecture.md §7.1-§7.2). What a map adds is finding that line:

1. *Room to drive*: the distance from every open cell to the nearest solid cell's face (SciPy's exact Euclidean
   distance transform); a planning cell of about ``PLAN_CELL`` is drivable when every map cell in it keeps the
   widest robot's half-width plus the margin (``sim.worlds.check.CLEARANCE``).
2. *Reachable places*: shortest paths from the station's cell over the drivable cells (SciPy's Dijkstra on the
   8-connected planning grid), one tree for every goal.
3. *Where the link dies*: the mean link (``sim.maps.coverage``) at every reachable cell, and along each cell's
   path the distance driven since the link was last alive. A goal is a cell where it is dead and has been for
   ``AFTER_DEATH`` to ``AFTER_DEATH + GOAL_SPAN`` metres of the way: the seed picks one.
4. *The line*: the tree's path to the goal, pulled taut over the drivable cells (each point joined to the farthest
   one it can see), then ``sim.worlds.build.scenario``'s waypoints, plan and checks; the driven path's clearance is
   read from the distance transform. A draw that fails is redrawn from the next sub-seed, as a family's is.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from link.radio import RadioParams
from sim.maps import coverage
from sim.maps.grid import Grid, Site
from sim.scenario import Scenario
from sim.station_script import WAYPOINT_RADIUS
from sim.world import Station
from sim.worlds import build, check

PLAN_CELL = 0.2  # m: the planning grid's cell (a map finer than this is planned on blocks of its cells)
SPEED = 1.0  # m/s: the operator's speed, the generated office's
GOAL_SPAN = 4.0  # m: goals lie AFTER_DEATH to AFTER_DEATH + GOAL_SPAN metres into the dead stretch
START_REACH = 10.0  # m: how far from the station the robot may start, if the station stands where it cannot
REDRAWS = 50
# m of clearance a map route keeps beyond the generated worlds' (sim.worlds.check.CLEARANCE) where it turns
# sharply (within TURN_ROOM_M of a corner of more than TURN_DEG): the scripted operator steers by an estimate a few
# decimetres behind the robot and turns late, and at a corner into a door that is a jamb. Measured on test
# doors: with no extra room the drive touched a 1.2 m door's jamb in 16 of 16 runs, with 0.25 m a 2 m door's in 3
# of 16, with 0.35 m a 2.4 m door's in none of 16.
EXTRA_ROOM = 0.35
NEED = check.CLEARANCE + EXTRA_ROOM
TURN_ROOM_M = 2.0  # m either side of a sharp corner where NEED holds; elsewhere CLEARANCE does
TURN_DEG = 30.0  # a corner sharper than this is driven slowly: ...
SLOW_D = 1.5  # m before it ...
SLOW = 0.4  # m/s, so the operator turns on the corner instead of overshooting it into a door's jamb
COMFORT = 1.2  # m of clearance below which a path pays for passing near a wall ...
PREFER = 3.0  # ... up to this many times its length, at the least drivable clearance


class RouteError(ValueError):
    """No route can be had on this map from this station; the message says why (the CLI names the map)."""


@dataclass(frozen=True, eq=False)
class Plan:
    """Everything about one (map, station, radio) that every seed's route shares: worked out once."""

    grid: Grid
    clear: np.ndarray  # m from each map cell's centre to the nearest solid cell's face (0 in solid cells)
    room: np.ndarray  # the least of ``clear`` over each planning cell
    f: int  # map cells per planning cell along each side
    drivable: np.ndarray  # planning grid
    start: tuple[int, int]  # planning cell the robot starts in
    start_point: tuple[float, float]  # its world (north, east)
    dist: np.ndarray  # m along the tree to each planning cell (inf: unreachable)
    pred: np.ndarray  # flat index of each cell's predecessor (-9999: none)
    margin_db: np.ndarray  # the mean link's margin at each planning cell (nan: unreachable)
    dead_run: np.ndarray  # m driven since the link was last alive, along the tree (nan: unreachable)
    goals: np.ndarray  # flat indices of the goal cells


def clearance(grid: Grid) -> np.ndarray:
    """Metres from each map cell's centre to the nearest solid cell's face (the map's surroundings count as
    solid where they are), 0 in solid cells."""
    from scipy import ndimage

    open_ = ~grid.solid
    if grid.outside_solid:
        open_ = np.pad(open_, 1, constant_values=False)
    d = ndimage.distance_transform_edt(open_) * grid.res - grid.res / 2
    if grid.outside_solid:
        d = d[1:-1, 1:-1]
    return np.where(grid.solid, 0.0, np.maximum(d, 0.0))


def _blocks_min(a: np.ndarray, f: int) -> np.ndarray:
    rows, cols = -(-a.shape[0] // f), -(-a.shape[1] // f)
    padded = np.zeros((rows * f, cols * f), dtype=a.dtype)
    padded[:a.shape[0], :a.shape[1]] = a
    return padded.reshape(rows, f, cols, f).min(axis=(1, 3))


def _centres(grid: Grid, f: int, rows: np.ndarray, cols: np.ndarray):
    """World (north, east) of planning cells' centres."""
    return grid.world_of_uv((cols * f + f / 2) * grid.res, (rows * f + f / 2) * grid.res)


def _graph(drivable: np.ndarray, room: np.ndarray, cell: float):
    """The 8-connected graph of the drivable planning cells (a sparse matrix over flat indices). A step costs its
    length, more where it passes nearer a wall than ``COMFORT`` (``room``: each cell's clearance), so a path keeps
    to the middle of a corridor and takes a door through its middle, as an operator would."""
    from scipy.sparse import coo_matrix

    rows, cols = drivable.shape
    idx = np.arange(rows * cols).reshape(rows, cols)
    src, dst, w = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = drivable[max(0, -dr):rows - max(0, dr), max(0, -dc):cols - max(0, dc)]
        b = drivable[max(0, dr):rows - max(0, -dr) or None, max(0, dc):cols - max(0, -dc) or None]
        both = a & b
        if dr and dc:  # a diagonal step needs both side cells too: no corner cutting through a wall's tip
            side1 = drivable[max(0, dr):rows - max(0, -dr) or None, max(0, -dc):cols - max(0, dc)]
            side2 = drivable[max(0, -dr):rows - max(0, dr), max(0, dc):cols - max(0, -dc) or None]
            both &= side1 & side2
        ia = idx[max(0, -dr):rows - max(0, dr), max(0, -dc):cols - max(0, dc)][both]
        ib = idx[max(0, dr):rows - max(0, -dr) or None, max(0, dc):cols - max(0, -dc) or None][both]
        tight = np.minimum(room.ravel()[ia], room.ravel()[ib])
        cost = cell * math.hypot(dr, dc) * (1.0 + PREFER * np.clip(1.0 - tight / COMFORT, 0.0, 1.0))
        src += [ia, ib]
        dst += [ib, ia]
        w += [cost, cost]
    n = rows * cols
    return coo_matrix((np.concatenate(w), (np.concatenate(src), np.concatenate(dst))), shape=(n, n)).tocsr()


@functools.lru_cache(maxsize=8)
def plan(site: Site, station: tuple[float, float], power_dbm: float, radio: RadioParams) -> Plan:
    """The shared part of every route from ``station`` (world frame) on ``site``'s map; RouteError if there is no
    drivable room near the station or no reachable place where the link dies."""
    from scipy.sparse.csgraph import dijkstra

    grid = site.grid()
    problem = grid.station_problem(*station)
    if problem:
        raise RouteError(f"the station {problem}")
    clear = clearance(grid)
    f = max(1, round(PLAN_CELL / grid.res))
    cell = f * grid.res
    room = _blocks_min(clear, f)
    drivable = room >= check.CLEARANCE
    rows, cols = np.nonzero(drivable)
    if not len(rows):
        raise RouteError(f"no place on the map leaves {check.CLEARANCE:.2f} m to every wall (a robot "
                         f"{check.ROBOT_WIDTH:.2f} m wide with {check.MARGIN} m of margin)")
    cn, ce = _centres(grid, f, rows, cols)
    near = np.hypot(cn - station[0], ce - station[1])
    start = None
    for k in np.argsort(near, kind="stable")[:400]:
        if near[k] > START_REACH:
            break
        if grid.crossed(station, (float(cn[k]), float(ce[k])))[0] == 0:
            start = (int(rows[k]), int(cols[k]))
            break
    if start is None:
        raise RouteError(f"no room for the robot within {START_REACH:g} m of the station (a drivable place "
                         "in plain sight of it)")
    graph = _graph(drivable, room, cell)
    flat_start = start[0] * drivable.shape[1] + start[1]
    dist, pred = dijkstra(graph, indices=flat_start, return_predecessors=True)
    dist = dist.reshape(drivable.shape)
    reach = np.isfinite(dist)
    rr, rc = np.nonzero(reach)
    pn, pe = _centres(grid, f, rr, rc)
    runs, metres = coverage.wall_counts(grid, station, pn, pe, cell)
    cov = coverage.predict(radio, power_dbm, site.wall_db, site.wall_db_per_m, station, pn, pe, runs, metres)
    margin = np.full(drivable.shape, np.nan)
    margin[rr, rc] = cov.margin_db
    band = check.band_db(radio)
    start_n, start_e = _centres(grid, f, np.array(start[0]), np.array(start[1]))
    if margin[start] < band:
        raise RouteError(f"the link is not alive where the robot starts (mean margin {margin[start]:.1f} dB, "
                         f"alive needs {band:.1f} dB)")
    # the way driven since the link was last alive, along the tree: cells in order of their distance
    dead_run = np.full(drivable.size, np.nan)
    flat_margin = margin.ravel()
    order = np.argsort(dist.ravel(), kind="stable")[:len(rr)]
    flat_dist = dist.ravel()
    for k in order.tolist():
        p = pred[k]
        if flat_margin[k] >= band or p < 0:
            dead_run[k] = 0.0
        else:
            dead_run[k] = dead_run[p] + (flat_dist[k] - flat_dist[p])
    dead = flat_margin <= -band
    goals = np.nonzero(dead & (dead_run >= build.AFTER_DEATH) & (dead_run <= build.AFTER_DEATH + GOAL_SPAN))[0]
    if not len(goals):
        raise RouteError("no reachable place where the link dies: every place the robot can drive to keeps the "
                         f"mean link within {band:.1f} dB of alive (a weaker radio, more wall loss, or another "
                         "station)")
    return Plan(grid, clear, room, f, drivable, start, (float(start_n), float(start_e)), dist, pred,
                margin, dead_run.reshape(drivable.shape), goals)


def _shortcut_room(p: Plan, a: tuple[float, float], b: tuple[float, float]) -> float:
    """The least planning-cell clearance on the straight line a -> b (planning-cell coordinates, fractional);
    0 where it leaves the map."""
    n = max(2, int(3 * math.hypot(b[0] - a[0], b[1] - a[1])) + 2)
    t = np.linspace(0.0, 1.0, n)
    r = np.floor(a[0] + (b[0] - a[0]) * t).astype(np.intp)
    c = np.floor(a[1] + (b[1] - a[1]) * t).astype(np.intp)
    ok = (r >= 0) & (r < p.room.shape[0]) & (c >= 0) & (c < p.room.shape[1])
    return float(p.room[r, c].min()) if ok.all() else 0.0


def taut(p: Plan, cells: list[tuple[int, int]]) -> list[tuple[float, float]]:
    """The path through ``cells`` pulled taut: from each kept point on to the farthest cell it can reach by a
    straight line that comes no nearer a wall than the stretch of path it replaces (so a shortcut never trades
    the middle of a door for its jamb)."""
    pts = [(r + 0.5, c + 0.5) for r, c in cells]
    room = [float(p.room[r, c]) for r, c in cells]
    out, i = [pts[0]], 0
    while i < len(pts) - 1:
        j = len(pts) - 1
        while j > i + 1 and _shortcut_room(p, pts[i], pts[j]) < min(room[i:j + 1]) - 1e-9:
            j -= 1
        out.append(pts[j])
        i = j
    return out


def path_to(p: Plan, goal: int) -> list[tuple[int, int]]:
    cols = p.drivable.shape[1]
    cells, k = [], int(goal)
    while k >= 0:
        cells.append(divmod(k, cols))
        k = int(p.pred[k])
    return cells[::-1]


def least_clearance(grid: Grid, clear: np.ndarray, path: list[tuple[float, float]], step: float = 0.05) -> float:
    """The least clearance (m to a solid cell's face) along a world-frame polyline, from the distance field
    ``clear`` of ``grid`` (``clearance``)."""
    best = math.inf
    for a, b in zip(path[:-1], path[1:], strict=False):
        n = max(2, int(math.dist(a, b) / step) + 2)
        t = np.linspace(0.0, 1.0, n)
        u, v = grid.uv(a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t)
        r = np.clip(np.floor(v / grid.res).astype(np.intp), 0, grid.rows - 1)
        c = np.clip(np.floor(u / grid.res).astype(np.intp), 0, grid.cols - 1)
        best = min(best, float(clear[r, c].min()))
    if len(path) == 1:
        u, v = grid.uv(path[0][0], path[0][1])
        r = min(max(math.floor(float(v) / grid.res), 0), grid.rows - 1)
        c = min(max(math.floor(float(u) / grid.res), 0), grid.cols - 1)
        best = float(clear[r, c])
    return best


def route_clearance(sc: Scenario) -> float:
    """The least clearance of a map world's driven route and resume route (m to a solid cell's face)."""
    grid = sc.site.grid()
    clear = clearance(grid)
    driven = check.steered_path(sc.start[:2], sc.route)
    resume = check.steered_path(driven[-1], sc.resume_route) if sc.resume_route else [driven[-1]]
    return min(least_clearance(grid, clear, driven), least_clearance(grid, clear, resume))


def near_corners(path: list[tuple[float, float]]) -> list[list[tuple[float, float]]]:
    """The stretches of ``path`` within TURN_ROOM_M of each corner sharper than TURN_DEG (along the path)."""
    out = []
    for k in range(1, len(path) - 1):
        if _turn_deg(path[k - 1], path[k], path[k + 1]) <= TURN_DEG:
            continue
        stretch = [path[k]]
        for nb in (path[k - 1], path[k + 1]):
            d = math.dist(path[k], nb)
            t = min(1.0, TURN_ROOM_M / d) if d > 0 else 0.0
            stretch.append((path[k][0] + (nb[0] - path[k][0]) * t, path[k][1] + (nb[1] - path[k][1]) * t))
        out.append([stretch[1], stretch[0], stretch[2]])
    return out


def _turn_deg(a, b, c) -> float:
    """How far the way a -> b -> c turns at b (degrees)."""
    h1 = math.atan2(b[1] - a[1], b[0] - a[0])
    h2 = math.atan2(c[1] - b[1], c[0] - b[0])
    return abs(math.degrees((h2 - h1 + math.pi) % (2 * math.pi) - math.pi))


def with_slowdowns(line: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """``line`` with a point SLOW_D before every corner sharper than TURN_DEG (where the leg is long enough), so
    the stretch into the corner can be paced on its own (``paced``)."""
    out = [line[0]]
    for a, b, c in zip(line[:-2], line[1:-1], line[2:], strict=True):
        d = math.dist(a, b)
        if _turn_deg(a, b, c) > TURN_DEG and d > SLOW_D + 0.5:
            k = (d - SLOW_D) / d
            out.append((a[0] + (b[0] - a[0]) * k, a[1] + (b[1] - a[1]) * k))
        out.append(b)
    out.append(line[-1])
    return out


def paced(route: tuple, slow: float = SLOW) -> tuple:
    """The operator's waypoints with the run into each sharp corner (a leg no longer than SLOW_D, give or take
    the waypoint radius) at ``slow``."""
    pts = [(w[0], w[1]) for w in route]
    out = []
    for k, w in enumerate(route):
        speed = w[2]
        if 0 < k < len(route) - 1:
            short = math.dist(pts[k - 1], pts[k]) <= SLOW_D + 2 * WAYPOINT_RADIUS + 0.05
            if short and _turn_deg(pts[k - 1], pts[k], pts[k + 1]) > TURN_DEG:
                speed = min(speed, slow)
        out.append((w[0], w[1], speed))
    return tuple(out)


def draw(site: Site, station: Station, radio: RadioParams, seed: int, name: str,
         description: str = "") -> tuple[Scenario, int]:
    """``(scenario, redraws)``: the first valid route of ``seed``'s sub-seeds on ``site`` from ``station``;
    RouteError when the map and station allow none."""
    pl = plan(site, (station.x, station.y), station.power_dbm, radio)
    last = ""
    for attempt, child in enumerate(np.random.SeedSequence(seed).spawn(REDRAWS)):
        rng = np.random.default_rng(child)
        goal = int(pl.goals[int(rng.integers(len(pl.goals)))])
        cells = path_to(pl, goal)
        pts = taut(pl, cells)
        n, e = _centres(pl.grid, pl.f, np.array([q[0] - 0.5 for q in pts]), np.array([q[1] - 0.5 for q in pts]))
        line = [pl.start_point] + [(float(a), float(b)) for a, b in zip(n[1:], e[1:], strict=True)]
        if len(line) < 2:
            last = "the goal is where the robot starts"
            continue
        size_w, size_h = pl.grid.cols * pl.grid.res, pl.grid.rows * pl.grid.res
        text = description or (f"A world from the map {site.file} ({size_w:.0f} m x {size_h:.0f} m at "
                               f"{pl.grid.res:g} m): the operator drives from the station to a place where the "
                               "link has died.")
        sc = build.scenario("map", text, (), (), station, radio, with_slowdowns(line), SPEED, site=site)
        sc = replace(sc, route=paced(sc.route), resume_route=paced(sc.resume_route))
        verdict = check.check(sc)
        driven = check.steered_path(sc.start[:2], sc.route)
        resume = check.steered_path(driven[-1], sc.resume_route) if sc.resume_route else [driven[-1]]
        room = min(least_clearance(pl.grid, pl.clear, driven), least_clearance(pl.grid, pl.clear, resume))
        turning = min((least_clearance(pl.grid, pl.clear, part)
                       for part in (*near_corners(driven), *near_corners(resume))), default=math.inf)
        problems = list(verdict.problems)
        if room < check.CLEARANCE - 0.05:
            problems.append(f"the route passes {room:.2f} m from a wall (needs {check.CLEARANCE:.2f} m)")
        if turning < NEED - 0.05:
            problems.append(f"the route turns sharply {turning:.2f} m from a wall (needs {NEED:.2f} m there)")
        if problems:
            last = "; ".join(problems)
            continue
        b = pl.grid.bounds()
        sc = replace(sc, name=name, file=name, seed=seed, bounds=(math.floor(b[0]), math.floor(b[1]),
                                                                    math.ceil(b[2]), math.ceil(b[3])),
                     description=f"{sc.description} Seed {seed}, {attempt} draw{'s' if attempt != 1 else ''} "
                                 "redrawn.")
        return sc, attempt
    raise RouteError(f"no valid route from seed {seed} in {REDRAWS} draws (the last: {last})")
