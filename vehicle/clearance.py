"""Free space the robot's range sensor has seen, and the corners of a return's route it lets the robot cut.

Why: a return that retraces its crumbs drives every corner the operator drove, and SmartRTL, which cuts across a
room to the doorway, gets the link back sooner there (issue 21: building, P95 14.34 s against SmartRTL's 14.20) but
touches the door frame doing it (17 contacts in 60 trials). The trail alone cannot say whether a shortcut is safe:
the robot's body swept only a band the width of the robot. A range sensor (lidar, depth camera; ``Readings.scan``)
says more: every beam crosses space that is free up to its return. A corner is cut only where every cell within
RTL_CUT_CLR of the shortcut (the robot's half-width plus a margin for the estimate and the follower, measured from
its centre) was seen free and none was ever seen occupied; anything unseen, and a robot without the sensor, keeps
the crumbs (docs/architecture.md §6).

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
HORIZON = 40.0  # m of route from the robot whose corners are cut: a plan's cost stays bounded on a long way home
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
