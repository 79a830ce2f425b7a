"""Free space the robot's range sensor has seen, and the corners of a return's route it lets the robot cut.

Why: a return that retraces its crumbs drives every corner the operator drove, and SmartRTL, which cuts across a
room to the doorway, gets the link back sooner there but touches the door frame doing it (issue 21; the figures are
in docs/evidence.md, "The measurements behind the vehicle's code"). The trail alone cannot say whether a shortcut is
safe: the robot's body swept only a band the width of the robot. A range sensor (lidar, depth camera;
``Readings.scan``) says more: every beam crosses space that is free up to its return. A corner is cut only where
every cell within RTL_CUT_CLR of the shortcut (the robot's half-width plus a margin for the estimate and the
follower, measured from its centre) was seen free and none was ever seen occupied; anything unseen, and a robot
without the sensor, keeps the crumbs (docs/architecture.md §6).

The route is also kept clear of what the sensor saw occupied (``keep_clear``): retraced crumbs run where the
operator's drive ran, a clip on a door frame included, and native returnlink touched a wall while returning in
generated office runs (issue 30). Each stretch is pushed sideways to RTL_CUT_CLR from every occupied cell, through
seen-free cells only; where the space is not there (a door, a pipe narrower than twice the clearance) it goes as far
from the walls as the space allows, at its own pace. Not slower there: slowing cost the generated culverts' returns
time to link and kept no return off a wall the move alone did not (docs/evidence.md, "The measurements
behind the vehicle's code"). A robot without the sensor keeps its route exactly.

The grid lives in the vehicle's estimated frame, the frame of the crumbs, so the drift of dead reckoning in a room
without fixes moves both together. A cell once seen occupied stays occupied (a person who walked through leaves a
cell the return will not cut through: the safe side). Memory is bounded by MAX_CELLS: past it the oldest tiles are
forgotten, and a forgotten cell is unseen, which only ever forbids a cut.

Pure in the house sense: no clock, no socket; mutable like the trail (the control loop feeds it every scan).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from vehicle.io import Scan

CELL = 0.25  # m: grid resolution, a fraction of any robot's half-width
STEP = 0.5 * CELL  # m: spacing of the samples along a beam that mark cells free (no cell a beam crosses is missed)
TILE_BITS = 5  # the grid is kept in tiles of 32 x 32 cells (8 m square), dense inside, created where seen
TILE = 1 << TILE_BITS
MAX_CELLS = 65536  # memory bound (64 tiles): about 4,000 m^2 seen, a building's floor
MAX_RANGE = 30.0  # m: a return further than this (or a non-finite one) is read as "nothing within the beam's range"
SPAN = 1 << 22  # cell indices within +-2^21 cells (+-524 km) of the origin; tile keys pack two tile indices
MAX_CUT = 12.0  # m: the longest shortcut considered (further than a scan reaches, nothing was seen free anyway)
HORIZON = 40.0  # m of route from the robot cut and kept clear: a plan's cost stays bounded on a long way home
GAIN = 0.5 * CELL  # m: the least clearance a move must gain, unless it reaches the clearance (less is grid noise)
HOLD = 0.5  # m along the route either side of a move that leans the same way before it tapers off
TAPER = 0.5  # m sideways per m along: how a move of the route leans in and out
FREE, OCCUPIED = 1, 2  # a cell's bits; 0 is unseen. Clear means seen free and never occupied: exactly FREE
_MAX_COORD = (SPAN // 2 - 1) * CELL  # a position beyond this is not in the grid (estimator glitch): not mapped


def _tiles(ix: np.ndarray, iy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell indices -> (the key of each cell's tile, its row and column within the tile)."""
    keys = ((ix >> TILE_BITS) + SPAN // 2) * SPAN + ((iy >> TILE_BITS) + SPAN // 2)
    return keys, ix & (TILE - 1), iy & (TILE - 1)


def _widest_gap(bearings: np.ndarray) -> float:
    """The widest angle between neighbouring beams of a sweep (round the circle: a sweep's ends are neighbours)."""
    b = np.sort(np.mod(bearings, 2.0 * math.pi))
    gaps = np.diff(np.concatenate([b, [b[0] + 2.0 * math.pi]]))
    return max(float(gaps.max()), 1e-6)


class FreeSpace:
    """Cells seen free or occupied by the range sensor, in tiles of TILE x TILE cells; a cell of no tile is unseen.

    Tiles rather than a cell per dict entry: a sweep books several hundred cells, and numpy sets them in a dense
    array in one indexing step each, where a dict took a Python call per cell (measured on the 10-minute tunnel
    bench: 56.0 us a tick with tiles, 58.3 with a dict entry per cell, 45.9 without the sensor)."""

    def __init__(self, max_cells: int = MAX_CELLS) -> None:
        self.tiles: dict[int, np.ndarray] = {}
        self.max_tiles = max(1, max_cells // (TILE * TILE))
        self.scans = 0

    @property
    def cells(self) -> int:
        """Cells held in memory (seen or not, a tile's worth at a time): what MAX_CELLS bounds."""
        return len(self.tiles) * TILE * TILE

    def seen(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every seen cell: its indices (x, y) and bits (FREE, OCCUPIED or both)."""
        xs, ys, bits = [], [], []
        for key, tile in self.tiles.items():
            lx, ly = np.nonzero(tile)
            tx, ty = key // SPAN - SPAN // 2, key % SPAN - SPAN // 2
            xs.append((tx << TILE_BITS) + lx)
            ys.append((ty << TILE_BITS) + ly)
            bits.append(tile[lx, ly])
        if not xs:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int8)
        return np.concatenate(xs), np.concatenate(ys), np.concatenate(bits)

    def scan(self, x: float, y: float, yaw: float, scan: Scan) -> None:
        """Book one scan taken at the estimated pose (x, y, yaw): each beam's cells up to a cell short of its
        return are free (no further than its neighbours are within a cell of it), the cell of a return within
        range is occupied. Beams with a bad bearing or range are skipped, not trusted."""
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            return
        if abs(x) > _MAX_COORD or abs(y) > _MAX_COORD:
            return
        try:  # a driver's scan is input: what is not numbers is dropped here, never raised into the tick
            bearings = np.asarray(scan.bearings, dtype=float)
            ranges = np.asarray(scan.ranges, dtype=float)
            reach = float(scan.max_range)
        except (TypeError, ValueError):
            return
        if bearings.shape != ranges.shape or bearings.ndim != 1 or not (0.0 < reach <= MAX_RANGE):
            return
        ok = np.isfinite(bearings) & ~np.isnan(ranges) & (ranges >= 0.0)
        bearings, ranges = bearings[ok], ranges[ok]
        if len(bearings) == 0:
            return
        hit = ranges < reach
        # free only as far as neighbouring beams are within a cell of each other: further out, a wall's end could
        # stand between two beams unseen, and the grid would call its cell free
        free_reach = min(reach, CELL / _widest_gap(bearings))
        free_to = np.minimum(np.where(hit, ranges - CELL, reach), free_reach)
        a = yaw + bearings
        ca, sa = np.cos(a), np.sin(a)
        s = np.arange(1, int(math.ceil(free_reach / STEP)) + 1) * STEP
        mask = s[None, :] <= free_to[:, None]
        fx = (x + ca[:, None] * s[None, :])[mask]
        fy = (y + sa[:, None] * s[None, :])[mask]
        self._book(np.floor(fx / CELL).astype(np.int64), np.floor(fy / CELL).astype(np.int64), FREE)
        hx, hy = x + ca[hit] * ranges[hit], y + sa[hit] * ranges[hit]
        self._book(np.floor(hx / CELL).astype(np.int64), np.floor(hy / CELL).astype(np.int64), OCCUPIED)
        self.scans += 1
        over = len(self.tiles) - self.max_tiles
        if over > 0:
            for k in list(self.tiles)[:over]:  # insertion order: the tiles seen first go first
                del self.tiles[k]

    def _book(self, ix: np.ndarray, iy: np.ndarray, bit: int) -> None:
        if len(ix) == 0:
            return
        keys, lx, ly = _tiles(ix, iy)
        first = int(keys[0])
        groups = [first] if bool((keys == first).all()) else np.unique(keys).tolist()
        tiles = self.tiles
        for k in groups:
            tile = tiles.get(k)
            if tile is None:
                tile = tiles[k] = np.zeros((TILE, TILE), dtype=np.int8)
            sel = (lx, ly) if len(groups) == 1 else (lx[keys == k], ly[keys == k])
            tile[sel] |= bit

    def window(self, ix0: int, iy0: int, nx: int, ny: int) -> np.ndarray:
        """The cells' bits from (ix0, iy0), nx by ny of them, as one dense array (unseen: 0)."""
        out = np.zeros((nx, ny), dtype=np.int8)
        for tx in range(ix0 >> TILE_BITS, ((ix0 + nx - 1) >> TILE_BITS) + 1):
            for ty in range(iy0 >> TILE_BITS, ((iy0 + ny - 1) >> TILE_BITS) + 1):
                tile = self.tiles.get((tx + SPAN // 2) * SPAN + (ty + SPAN // 2))
                if tile is None:
                    continue
                x0, y0 = tx << TILE_BITS, ty << TILE_BITS
                ax, bx = max(ix0, x0), min(ix0 + nx, x0 + TILE)
                ay, by = max(iy0, y0), min(iy0 + ny, y0 + TILE)
                out[ax - ix0:bx - ix0, ay - iy0:by - iy0] = tile[ax - x0:bx - x0, ay - y0:by - y0]
        return out

    def clear(self, a: np.ndarray, b: np.ndarray, radius: float) -> bool:
        """Whether every cell that comes within ``radius`` of segment a-b was seen free and none occupied (a cell
        counts if any part of it comes that close)."""
        ax, ay, bx, by = float(a[0]), float(a[1]), float(b[0]), float(b[1])
        if not all(math.isfinite(v) for v in (ax, ay, bx, by)) or radius <= 0.0:
            return False
        r = radius + CELL * math.sqrt(0.5)  # a cell's centre this close: some of the cell is within radius
        x0, x1 = math.floor((min(ax, bx) - r) / CELL), math.floor((max(ax, bx) + r) / CELL)
        y0, y1 = math.floor((min(ay, by) - r) / CELL), math.floor((max(ay, by) + r) / CELL)
        if max(abs(x0), abs(x1), abs(y0), abs(y1)) >= SPAN // 2:
            return False
        ix, iy = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1), indexing="ij")
        cx, cy = (ix + 0.5) * CELL, (iy + 0.5) * CELL
        dx, dy = bx - ax, by - ay
        L2 = dx * dx + dy * dy
        u = np.clip(((cx - ax) * dx + (cy - ay) * dy) / L2, 0.0, 1.0) if L2 > 1e-18 else np.zeros_like(cx)
        near = np.hypot(cx - (ax + u * dx), cy - (ay + u * dy)) <= r
        keys, lx, ly = _tiles(ix[near], iy[near])
        for k in np.unique(keys).tolist():
            tile = self.tiles.get(k)
            if tile is None:
                return False
            sel = keys == k
            if not bool((tile[lx[sel], ly[sel]] == FREE).all()):
                return False
        return True


def shortcut(points: np.ndarray, speeds: np.ndarray, free: FreeSpace | None,
             radius: float) -> tuple[np.ndarray, np.ndarray]:
    """``points`` with the corners cut that ``free`` shows clear by ``radius``: from each kept point, straight on
    to the furthest later point (within MAX_CUT) the segment to which, and every one before it, is clear. A cut
    drives at the slowest pace of the stretches it replaces. Never longer than ``points``; the first and last
    points are kept, so the route still starts at the robot and ends at its target. ``radius`` 0 or no free space:
    unchanged."""
    n = len(points)
    if free is None or radius <= 0.0 or n < 3 or not free.tiles:
        return points, speeds
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
    out, sp = [0], []
    i = 0
    while i < n - 1:
        j = i + 1
        while (j + 1 < n and cum[j + 1] <= HORIZON and cum[j + 1] - cum[i] <= MAX_CUT
               and free.clear(points[i], points[j + 1], radius)):
            j += 1
        paces = speeds[i:j]
        paces = paces[np.isfinite(paces)]
        sp.append(float(paces.min()) if len(paces) else math.nan)
        out.append(j)
        i = j
    sp.append(float(speeds[-1]))
    return points[out], np.array(sp)


def _spread(move: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Per sample at ``s`` metres along (ascending), the largest ``move`` of any sample within HOLD of it, less
    TAPER per metre beyond: max_j (move_j - TAPER max(0, |s_i - s_j| - HOLD))."""
    k = np.arange(len(s))
    held = move.copy()  # within HOLD either way: a sliding maximum over the few samples there
    lo, hi = np.searchsorted(s, s - HOLD, side="left"), np.searchsorted(s, s + HOLD, side="right")
    for off in range(1, int(max((hi - k).max(initial=0), (k - lo).max(initial=0))) + 1):
        ahead, behind = np.minimum(k + off, len(s) - 1), np.maximum(k - off, 0)
        held = np.where(k + off < hi, np.maximum(held, move[ahead]), held)
        held = np.where(k - off >= lo, np.maximum(held, move[behind]), held)
    # beyond HOLD: the best of move_j - TAPER s_j further on, and of move_j + TAPER s_j further back
    on = np.maximum.accumulate((move - TAPER * s)[::-1])[::-1]
    back = np.maximum.accumulate(move + TAPER * s)
    far_on = np.searchsorted(s, s + HOLD, side="left")
    far_back = np.searchsorted(s, s - HOLD, side="right") - 1
    out = held
    out = np.where(far_on < len(s), np.maximum(out, on[np.minimum(far_on, len(s) - 1)] + TAPER * (s + HOLD)), out)
    out = np.where(far_back >= 0, np.maximum(out, back[np.maximum(far_back, 0)] - TAPER * (s - HOLD)), out)
    return out


def keep_clear(points: np.ndarray, speeds: np.ndarray, free: FreeSpace | None,
               radius: float) -> tuple[np.ndarray, np.ndarray]:
    """``points`` pushed sideways away from the cells ``free`` saw occupied, to ``radius`` from each where seen free
    space allows, and their ``speeds`` (a moved point keeps the pace of the stretch it was on).

    The first HORIZON metres are resampled every CELL. Each sample short of ``radius`` looks along the route's
    normal, both ways, up to ``radius``, through cells seen free only (a move never crosses or ends in an unseen or
    occupied cell), for the least move that puts the nearest occupied cell ``radius`` away, or, short of that, the
    move that gains the most, if that is at least GAIN: the grid places a wall to within a cell, smeared by the
    estimate the scans were booked with, so a smaller gain (the operator's crumbs through a door are as central as
    the grid can tell) is noise, and so is a move the samples around it do not share (a wall pushes every sample
    that comes within the clearance of it): each takes the median move of the five around it. Its neighbours within
    HOLD lean the same way, then less by TAPER per metre, so the route bends smoothly; moves fade out to nothing at
    the start (the robot) and the end (its target), which stay put, and never turn the route back on itself. No
    point ends closer to an occupied cell than it was, or than ``radius``. Samples that did not move are dropped
    again, so a stretch with nothing near it keeps its crumbs exactly. ``radius`` 0 or no free space: unchanged.
    Bounded: at most HORIZON / CELL samples (plus the route's own points), each searching a fixed neighbourhood."""
    n = len(points)
    if (free is None or radius <= 0.0 or n < 2 or len(speeds) != n or not free.tiles
            or not np.all(np.isfinite(points))):
        return points, speeds
    if float(np.abs(points).max()) + 2.0 * radius + HORIZON > _MAX_COORD:
        return points, speeds
    original, speeds0 = points, speeds
    points, speeds, seg, cum, m = _split_at_horizon(points, speeds)
    p, owner, vertex, s = _samples(points, seg, cum, m)
    side = _Sideways(p, s, _Window(free, p, radius), radius)
    d0 = side.window.nearest(p)
    want = np.flatnonzero(d0 < radius)
    if len(want) == 0:
        return original, speeds0
    shift, dist, took = _first_moves(side, want, d0)
    if took:
        _despike(side, shift, dist, d0)
    if np.any(shift != 0.0):
        _lean(side, shift, dist, d0, s)
    out = p + shift[:, None] * side.normal
    alive = _untangle(side, shift, dist, d0, out)
    moved = shift != 0.0
    if not moved.any():
        return original, speeds0
    keep = vertex | moved
    keep[1:] |= moved[:-1]
    keep[:-1] |= moved[1:]
    keep[0] = keep[-1] = True
    keep &= alive
    pts = np.vstack([out[keep], points[m + 1:]])
    return pts, np.concatenate([speeds[owner[keep]], speeds[m + 1:]])


def _split_at_horizon(points: np.ndarray, speeds: np.ndarray):
    """(points, speeds, segment lengths, distance along at each point, m): ``m`` the segments that start within
    HORIZON; when the last of them ends far beyond, it is split at HORIZON (the work stays bounded)."""
    seg = np.hypot(*np.diff(points, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    m = min(max(1, int(np.searchsorted(cum, HORIZON, side="left"))), len(points) - 1)
    if cum[m] > HORIZON + CELL:
        u = (HORIZON - cum[m - 1]) / seg[m - 1]
        points = np.vstack([points[:m], points[m - 1] + u * (points[m] - points[m - 1]), points[m:]])
        speeds = np.concatenate([speeds[:m], speeds[m - 1:]])
        seg = np.concatenate([seg[:m - 1], [HORIZON - cum[m - 1], cum[m] - HORIZON], seg[m:]])
        cum = np.concatenate([cum[:m], [HORIZON], cum[m:]])
    return points, speeds, seg, cum, m


def _samples(points: np.ndarray, seg: np.ndarray, cum: np.ndarray, m: int):
    """The first ``m`` segments resampled every CELL, and the end of the last: (samples, the point each lies
    after, whether it is a point of the route itself, its distance along)."""
    counts = np.maximum(1, np.ceil(seg[:m] / CELL).astype(np.int64))
    owner = np.repeat(np.arange(m), counts)  # the segment each sample lies on
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    u = (np.arange(len(owner)) - first[owner]) / counts[owner]
    p = np.vstack([points[owner] + u[:, None] * (points[owner + 1] - points[owner]), points[m:m + 1]])
    owner = np.concatenate([owner, [m]])
    vertex = np.concatenate([u == 0.0, [True]])
    s = np.concatenate([cum[owner[:-1]] + u * seg[owner[:-1]], [cum[m]]])
    return p, owner, vertex, s


class _Window:
    """The grid around the samples, dense: every cell any candidate's nearest-occupied search can touch."""

    def __init__(self, free: FreeSpace, p: np.ndarray, radius: float) -> None:
        self.radius = radius
        reach = int(math.ceil(radius / CELL)) + 1
        margin = radius + (reach + 1) * CELL
        self.ix0 = ix0 = int(math.floor((p[:, 0].min() - margin) / CELL))
        self.iy0 = iy0 = int(math.floor((p[:, 1].min() - margin) / CELL))
        self.grid = free.window(ix0, iy0, int(math.floor((p[:, 0].max() + margin) / CELL)) - ix0 + 1,
                                int(math.floor((p[:, 1].max() + margin) / CELL)) - iy0 + 1)
        ox, oy = np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1), indexing="ij")
        near = ((np.maximum(np.abs(ox) - 1, 0) ** 2 + np.maximum(np.abs(oy) - 1, 0) ** 2) * CELL * CELL
                <= radius * radius)
        ox, oy = ox[near], oy[near]
        self.ny = self.grid.shape[1]
        self.occupied = ((self.grid & OCCUPIED) != 0).ravel()  # flat: a cell's neighbours are fixed index offsets
        self.around = ox * self.ny + oy

    def cells(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (np.floor(q[..., 0] / CELL).astype(np.int64) - self.ix0,
                np.floor(q[..., 1] / CELL).astype(np.int64) - self.iy0)

    def nearest(self, q: np.ndarray) -> np.ndarray:
        """Distance from each position to the centre of the nearest occupied cell, capped at ``radius``."""
        ny = self.ny
        cx, cy = self.cells(q)
        flat = q.reshape(-1, 2)
        at, nb = np.nonzero(self.occupied[(cx * ny + cy).reshape(-1, 1) + self.around])  # (position, neighbour)
        out = np.full(len(flat), self.radius)
        if len(at):
            cell = (cx * ny + cy).reshape(-1)[at] + self.around[nb]
            d = np.hypot((cell // ny + self.ix0 + 0.5) * CELL - flat[at, 0],
                         (cell % ny + self.iy0 + 0.5) * CELL - flat[at, 1])
            np.minimum.at(out, at, d)
        return out.reshape(q.shape[:-1])

    def clear_cell(self, q: np.ndarray) -> np.ndarray:
        cx, cy = self.cells(q)
        return self.grid[cx, cy] == FREE


class _Sideways:
    """The moves a sample may take: along the route's normal, both ways, in steps of half a cell up to the
    clearance, no further sideways than the sample is along from either fixed end of the route."""

    def __init__(self, p: np.ndarray, s: np.ndarray, window: _Window, radius: float) -> None:
        self.p, self.window, self.radius = p, window, radius
        tangent = np.zeros_like(p)
        tangent[1:-1] = p[2:] - p[:-2]
        tangent[0], tangent[-1] = p[1] - p[0], p[-1] - p[-2]
        norm = np.hypot(tangent[:, 0], tangent[:, 1])
        self.tangent = tangent
        self.normal = np.where(norm[:, None] > 1e-12, np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
                               / np.maximum(norm, 1e-12)[:, None], 0.0)
        self.step = 0.5 * CELL
        self.half = max(1, int(math.floor(radius / self.step + 1e-9)))
        self.offsets = np.arange(-self.half, self.half + 1) * self.step  # index ``half`` is no move
        # a move fades in from the route's fixed ends: no further sideways than the sample is along from either
        fade = np.minimum(s, s[-1] - s)
        fade[0] = fade[-1] = 0.0
        self.fade = fade

    def candidates(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For samples ``rows``: whether each offset may be taken (reached through free cells, within the fade)
        and its clearance."""
        half, offsets = self.half, self.offsets
        q = self.p[rows, None, :] + offsets[None, :, None] * self.normal[rows, None, :]
        ok = self.window.clear_cell(q)
        # reachable: every offset between here and it is a free cell too (a move never jumps a wall)
        ok[:, half + 1:] = np.cumprod(ok[:, half + 1:], axis=1).astype(bool)
        ok[:, :half] = np.cumprod(ok[:, :half][:, ::-1], axis=1)[:, ::-1].astype(bool)
        ok &= np.abs(offsets)[None, :] <= self.fade[rows, None] + 1e-9
        ok[:, half] = True
        return ok, self.window.nearest(q)

    def take(self, rows: np.ndarray, moves: np.ndarray, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For samples ``rows``: whether each may take its move in ``moves`` (reachable, and keeping at least
        ``floor`` of clearance), and the clearance it would have there."""
        ok, d = self.candidates(rows)
        j = self.half + np.round(moves / self.step).astype(np.int64)
        dj = d[np.arange(len(rows)), j]
        return ok[np.arange(len(rows)), j] & (dj >= floor), dj


def _first_moves(side: _Sideways, want: np.ndarray, d0: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """(move, clearance) of every sample, and whether any moved: for each of ``want`` (short of the clearance) the
    least move that reaches the clearance, else the most clearance (ties: the smaller move), if it is a gain of at
    least GAIN; the others stay."""
    radius, offsets = side.radius, side.offsets
    shift = np.zeros(len(side.p))
    dist = d0.copy()
    ok, d = side.candidates(want)
    rows = np.arange(len(want))
    goal = ok & (d >= radius)
    score = np.where(goal, 10.0 * radius - np.abs(offsets)[None, :],
                     np.where(ok, d - 1e-6 * np.abs(offsets)[None, :], -np.inf))
    best = np.argmax(score, axis=1)
    take = goal[rows, best] | (d[rows, best] >= d0[want] + GAIN - 1e-9)
    best = np.where(take, best, side.half)
    shift[want] = offsets[best]
    dist[want] = d[rows, best]
    return shift, dist, bool(take.any())


def _despike(side: _Sideways, shift: np.ndarray, dist: np.ndarray, d0: np.ndarray) -> None:
    """A move its neighbours do not share is the grid's noise, not a wall (a wall within the clearance pushes
    every sample that comes near it): each sample takes the median move of the five around it, where it may."""
    despike = np.median(np.lib.stride_tricks.sliding_window_view(np.pad(shift, 2, mode="edge"), 5), axis=1)
    change = np.flatnonzero(despike != shift)
    if len(change):
        fine, dj = side.take(change, despike[change], np.minimum(side.radius, d0[change]))
        shift[change] = np.where(fine, despike[change], 0.0)
        dist[change] = np.where(fine, dj, d0[change])


def _lean(side: _Sideways, shift: np.ndarray, dist: np.ndarray, d0: np.ndarray, s: np.ndarray) -> None:
    """Neighbours lean the same way (where both ways are wanted, neither), where that is free and keeps, or
    reaches, the clearance."""
    step = side.step
    up, down = _spread(np.maximum(shift, 0.0), s), _spread(np.maximum(-shift, 0.0), s)
    lean = np.where(down <= 0.0, up, np.where(up <= 0.0, -down, 0.0))
    lean = np.trunc(lean / step + 1e-9) * step
    more = np.flatnonzero((np.abs(lean) > np.abs(shift) + 1e-9) & (lean * shift >= 0.0))
    if len(more):
        fine, dj = side.take(more, lean[more], np.minimum(side.radius, np.maximum(d0[more], dist[more])))
        shift[more[fine]] = lean[more[fine]]
        dist[more[fine]] = dj[fine]


def _untangle(side: _Sideways, shift: np.ndarray, dist: np.ndarray, d0: np.ndarray, out: np.ndarray) -> np.ndarray:
    """The samples kept (the others dropped) so that the straight line between neighbours stays in free cells and
    goes forward (from one end to the other, and along the route where each end lies); ``shift``, ``dist`` and
    ``out`` updated where a moved sample is sent back.

    A line that leaves free cells (a move toward the inside of a bend can cross it) sends its moved ends back. A
    line that goes backward (the inside of a bend, or two crumbs a few cm apart moved by slightly different
    normals) loses a moved end instead: sent back, the crumb would stay between moved neighbours, a zigzag of
    0.5 m legs the follower crawls through at half the pace it was driven (docs/evidence.md)."""
    p, tangent = side.p, side.tangent
    k = len(p)
    alive = np.ones(k, dtype=bool)
    for _ in range(2 * k):
        moved = shift != 0.0
        at = np.flatnonzero(alive)
        a, b = at[:-1], at[1:]
        involved = moved[a] | moved[b]
        walled = ~side.window.clear_cell(0.5 * (out[a] + out[b])) & involved
        if walled.any():
            back = np.zeros(k, dtype=bool)
            back[a[walled]] = True
            back[b[walled]] = True
            back &= moved
            shift[back], dist[back], out[back] = 0.0, d0[back], p[back]
            continue
        step_ab = out[b] - out[a]
        backward = (((step_ab * (p[b] - p[a])).sum(axis=1) <= 0.0) | ((step_ab * tangent[a]).sum(axis=1) <= 0.0)
                    | ((step_ab * tangent[b]).sum(axis=1) <= 0.0)) & involved
        if not backward.any():
            break
        i = int(np.flatnonzero(backward)[0])
        drop = b[i] if moved[b[i]] and b[i] != k - 1 else a[i]
        if drop == 0 or not moved[drop]:  # neither end may go: the moved one goes back instead
            drop = a[i] if moved[a[i]] else b[i]
            shift[drop], dist[drop], out[drop] = 0.0, d0[drop], p[drop]
            continue
        alive[drop] = False
    return alive
