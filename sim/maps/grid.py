"""A map's cells as a simulated place: solid for the robot, lossy for the radio, visible to the range sensor.

The simulator's frame is the vehicle's local frame: x north, y east (``sim.world``). A map's frame is REP 103's:
x east, y north. So a map point (x, y) is the world point (north, east) = (y, x), and a run on a map flies in the
map's own frame: the vehicle's LOCAL_POSITION_NED north and east are the map's y and x. The map's origin yaw, if
any, turns the grid inside that frame.

What a real map needs that drawn walls did not (a map holds 10^4-10^6 occupied cells):

- *The robot's walls* are the edges between solid and open cells, merged into the longest straight runs along
  the grid's rows and columns: a few thousand pymunk segments, not one shape per cell.
- *The radio's walls* are counted on the grid: the line of sight is sampled every half cell, and its loss is
  ``wall_db`` for every run of solid cells it crosses plus ``wall_db_per_m`` for every metre of them (a partition
  is a crossing, rock between two drifts is metres). One vectorised pass per line, no segment query.
- *The range sensor's beams* march over the same grid.

Unknown cells are solid (a place nobody mapped is no place to drive or to see through) unless the scenario says
``unknown = "free"``; the map's surroundings count as unknown. The exception is a speck: an unknown patch under
``SPECK_M2`` enclosed by free cells, the floor between two rays of a laser's fan, which is free.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymunk

from sim.maps import mapfile
from sim.world import WALL, Station, World

UNKNOWN = ("wall", "free")
DEFAULT_WALL_DB = 8.0  # dB a crossing of a run of solid cells (an interior wall at 2.4 GHz: 3-15 dB)
DEFAULT_WALL_DB_PER_M = 4.0  # dB per metre of solid cells crossed (rock, concrete, whatever the map never saw into)
SEGMENT_RADIUS = 0.01  # m: a collision edge's half-thickness (the cell edge itself is the wall's face)
BODY_FITS = 0.3  # m: an open place is one a robot's centre may reach if it is this far from every solid cell ...
SPECK_M2 = 0.5  # m2: an unknown patch smaller than this, enclosed by free cells, is floor a laser missed
NEAR_CELL = 0.2  # m: the blocks that question is asked on
TILE = 8.0  # m: walls enter the physics a tile at a time, as a body comes within a tile of them
LOOK_EVERY = 10  # steps between looks at where the bodies are (0.2 s: 0.4 m at 2 m/s, a twentieth of a tile)
BODY_REACH = 0.6  # m: ... and its body touches what lies within this of such places (robot radii are 0.35-0.4 m)


@dataclass(frozen=True)
class Site:
    """What a scenario says about its map: the YAML file (a resolved path), the rules for unknown cells and the
    radio's wall loss. A small value (the cells are read, once per process, by ``mapfile.read``)."""

    file: str
    unknown: str = "wall"
    wall_db: float = DEFAULT_WALL_DB
    wall_db_per_m: float = DEFAULT_WALL_DB_PER_M
    digest: str = ""  # the map's content when the scenario was written ("" : not checked)

    def grid(self) -> Grid:
        return grid_of(mapfile.read(self.file), self.unknown == "free")

    def world(self, denied: tuple = (), stations: tuple[Station, ...] = ()) -> GridWorld:
        return GridWorld(self, self.grid(), denied, stations)


class Grid:
    """The solid cells of a map in the world frame, and the geometry asked of them. ``solid[row, col]`` with row
    0 at the map's bottom; cell (row, col) covers u in [col, col + 1) x res and v in [row, row + 1) x res, where
    (u, v) is the map frame turned by the origin's yaw about the origin."""

    def __init__(self, solid: np.ndarray, resolution: float, origin: tuple[float, float, float],
                 outside_solid: bool) -> None:
        self.solid = solid
        self.res = resolution
        self.ox, self.oy, self.yaw = origin
        self.cos, self.sin = math.cos(self.yaw), math.sin(self.yaw)
        self.outside_solid = outside_solid
        self.rows, self.cols = solid.shape
        # one flat lookup with a border cell all round that stands for everything off the map
        padded = np.full((self.rows + 2, self.cols + 2), outside_solid, dtype=bool)
        padded[1:-1, 1:-1] = solid
        self._flat = padded.ravel()
        self._stride = self.cols + 2
        self._edges: np.ndarray | None = None

    # ----- frames --------------------------------------------------------------------------------------------
    def draw(self, ax, zorder: float = 0) -> None:
        """Solid cells dark, open ones white, under a plan view (east right, north up: the map frame itself, so no
        axes swap), turned by the map origin's yaw about the origin."""
        from matplotlib import transforms  # (plots only: reading a map needs no matplotlib)

        shade = np.where(self.solid, 0.35, 1.0)
        extent = (self.ox, self.ox + self.cols * self.res, self.oy, self.oy + self.rows * self.res)
        im = ax.imshow(shade, origin="lower", extent=extent, cmap="gray", vmin=0.0, vmax=1.0,
                       interpolation="nearest", zorder=zorder)
        if self.yaw:
            im.set_transform(transforms.Affine2D().rotate_around(self.ox, self.oy, self.yaw) + ax.transData)

    def uv(self, north: np.ndarray | float, east: np.ndarray | float):
        """World (north, east) to the grid's (u, v) metres."""
        dx, dy = np.asarray(east) - self.ox, np.asarray(north) - self.oy
        return self.cos * dx + self.sin * dy, -self.sin * dx + self.cos * dy

    def world_of_uv(self, u, v):
        """The grid's (u, v) metres to world (north, east)."""
        u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
        x = self.ox + self.cos * u - self.sin * v
        y = self.oy + self.sin * u + self.cos * v
        return y, x

    def cell_centre(self, row, col):
        """World (north, east) of cell centres."""
        return self.world_of_uv((np.asarray(col) + 0.5) * self.res, (np.asarray(row) + 0.5) * self.res)

    def solid_at(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Whether each (u, v) lies in a solid cell (off the map: ``outside_solid``)."""
        col = np.clip(np.floor(u / self.res), -1, self.cols).astype(np.intp) + 1
        row = np.clip(np.floor(v / self.res), -1, self.rows).astype(np.intp) + 1
        return self._flat[row * self._stride + col]

    def solid_at_inside(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``solid_at`` for points known to lie on the map (u, v >= 0 and inside): truncation is the floor there,
        and nothing needs clipping (the line of sight's and the scan's hot path)."""
        inv = 1.0 / self.res
        return self._flat[((v * inv).astype(np.intp) + 1) * self._stride + (u * inv).astype(np.intp) + 1]

    def _on(self, u: float, v: float, spare: float = 0.0) -> bool:
        """Whether (u, v) lies ``spare`` metres or more inside the map's edges."""
        return spare <= u < self.cols * self.res - spare and spare <= v < self.rows * self.res - spare

    def is_solid(self, north: float, east: float) -> bool:
        u, v = self.uv(north, east)
        return bool(self.solid_at(np.atleast_1d(u), np.atleast_1d(v))[0])

    def station_problem(self, north: float, east: float) -> str | None:
        """Why a station cannot stand at world (north, east): off the map or in a solid cell; None if it can."""
        u, v = self.uv(north, east)
        row, col = math.floor(float(v) / self.res), math.floor(float(u) / self.res)
        if not (0 <= row < self.rows and 0 <= col < self.cols):
            return "is off the map"
        if self.solid[row, col]:
            return "stands in an occupied cell" + (" (or an unknown one, which counts as a wall)"
                                                   if self.outside_solid else "")
        return None

    def bounds(self) -> tuple[float, float, float, float]:
        """(north_min, east_min, north_max, east_max) of the map's corners in the world frame."""
        n, e = self.world_of_uv(np.array([0.0, self.cols, 0.0, self.cols]) * self.res,
                                np.array([0.0, 0.0, self.rows, self.rows]) * self.res)
        return float(n.min()), float(e.min()), float(n.max()), float(e.max())

    # ----- the radio -----------------------------------------------------------------------------------------
    def crossed(self, a: tuple[float, float], b: tuple[float, float]) -> tuple[int, float]:
        """(runs of solid cells crossed, metres of solid cells) along the straight line a -> b (world frame),
        sampled every half cell."""
        ua, va = self.uv(a[0], a[1])
        ub, vb = self.uv(b[0], b[1])
        length = math.hypot(float(ub - ua), float(vb - va))
        step = self.res / 2
        n = max(2, int(length / step) + 1)
        t = (np.arange(n) + 0.5) / n  # each sample stands for length / n of the line
        us, vs = ua + (ub - ua) * t, va + (vb - va) * t
        # both ends on the map: every sample is (the map is convex), so the fast lookup serves
        inside = (self.solid_at_inside if self._on(ua, va) and self._on(ub, vb) else self.solid_at)(us, vs)
        if not inside.any():
            return 0, 0.0
        runs = int(inside[0]) + int(np.count_nonzero(inside[1:] & ~inside[:-1]))
        return runs, float(np.count_nonzero(inside)) * length / n

    # ----- the range sensor ----------------------------------------------------------------------------------
    def ranges(self, north: float, east: float, angles: np.ndarray, reach: float) -> np.ndarray:
        """Distance along each world angle (from north toward east) to the first solid cell within ``reach``
        (inf where none), marched every half cell."""
        step = self.res / 2
        k = np.arange(1, int(reach / step) + 1) * step
        dn, de = np.cos(angles)[:, None] * k, np.sin(angles)[:, None] * k
        u, v = self.uv(north + dn, east + de)
        u0, v0 = self.uv(north, east)
        look = self.solid_at_inside if self._on(float(u0), float(v0), reach + step) else self.solid_at
        hit = look(u.ravel(), v.ravel()).reshape(u.shape)
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
        return np.where(first >= 0, k[np.maximum(first, 0)] - step / 2, np.inf)

    # ----- the robot's walls ---------------------------------------------------------------------------------
    def edges(self) -> np.ndarray:
        """Every edge between a solid cell and an open one a robot's body can reach (the map's border too, where
        off the map is solid), merged into maximal straight runs: rows of (u1, v1, u2, v2) in metres of the grid's
        frame. Worked out once per grid."""
        if self._edges is None:
            self._edges = self._edge_runs()
        return self._edges

    def _edge_runs(self) -> np.ndarray:
        """``edges``: open cells no body fits near (the slivers between a laser's rays in unknown space, which
        are most of a real map's edges) are taken as solid first: no robot can touch them. Where a body fits is
        worked out on blocks of cells about NEAR_CELL wide (any solid cell makes a block solid), which only ever
        keeps more edges than needed."""
        from scipy import ndimage

        f = max(1, round(NEAR_CELL / self.res))
        rows, cols = -(-self.rows // f), -(-self.cols // f)
        block = np.full((rows * f, cols * f), self.outside_solid, dtype=bool)
        block[:self.rows, :self.cols] = self.solid
        coarse = block.reshape(rows, f, cols, f).any(axis=(1, 3))
        padded = np.pad(~coarse, 1, constant_values=not self.outside_solid)
        room = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * (f * self.res)
        fits = room >= BODY_FITS + f * self.res
        near = (ndimage.distance_transform_edt(~fits) * (f * self.res) <= BODY_REACH + f * self.res
                if fits.any() else fits)
        near = np.repeat(np.repeat(near, f, axis=0), f, axis=1)[:self.rows, :self.cols]
        s = np.zeros((self.rows + 2, self.cols + 2), dtype=bool)
        s[:] = self.outside_solid
        s[1:-1, 1:-1] = self.solid | ~near
        out = []
        # horizontal edges: between padded rows r and r + 1 (grid line v = r x res), along the columns
        change = s[:-1, 1:-1] != s[1:, 1:-1]
        out.append(_runs(change, lambda line, c0, c1: (c0, line, c1, line)))
        # vertical edges: between padded columns c and c + 1 (grid line u = c x res), along the rows
        change = (s[1:-1, :-1] != s[1:-1, 1:]).T
        out.append(_runs(change, lambda line, r0, r1: (line, r0, line, r1)))
        edges = np.concatenate(out, axis=0) if out else np.zeros((0, 4))
        return edges * self.res


def _runs(change: np.ndarray, place) -> np.ndarray:
    """The maximal runs of True along each row of ``change`` as (line, start, end) placed by ``place``."""
    padded = np.zeros((change.shape[0], change.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = change
    d = np.diff(padded, axis=1)
    line_s, start = np.nonzero(d == 1)
    line_e, end = np.nonzero(d == -1)
    # nonzero scans row by row, so starts and ends pair up in order
    return np.stack(place(line_s.astype(float), start.astype(float), end.astype(float)), axis=1) \
        if len(line_s) else np.zeros((0, 4))


def specks(unknown: np.ndarray, free: np.ndarray, resolution: float) -> np.ndarray:
    """Unknown cells in small patches (under SPECK_M2) with no occupied or off-map cell beside them: the floor a
    laser's fan of rays missed between two rays, inside space it saw free. Counted as walls they would make the
    radio die in an open passage and the robot swerve round nothing."""
    from scipy import ndimage

    labels, n = ndimage.label(unknown, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return np.zeros_like(unknown)
    size = np.bincount(labels.ravel(), minlength=n + 1)
    # a patch that touches anything but free cells (an occupied cell, the map's edge) is not enclosed by free space
    touches = np.zeros(n + 1, dtype=bool)
    grown = ndimage.binary_dilation(unknown, structure=np.ones((3, 3), dtype=bool))
    ring = grown & ~unknown & ~free
    if ring.any():
        near = ndimage.maximum_filter(labels, size=3)
        touches[np.unique(near[ring])] = True
    edge = np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])
    touches[np.unique(edge)] = True
    small = (size * resolution * resolution < SPECK_M2) & ~touches
    small[0] = False
    return small[labels]


def grid_of(m: mapfile.OccupancyMap, unknown_free: bool) -> Grid:
    """The solid grid of map ``m``: occupied cells, and unknown ones unless ``unknown_free`` (save ``specks``:
    unknown patches enclosed by free space are floor). Cached on the map (a campaign's trials build it once per
    process)."""
    key = "_grid_free" if unknown_free else "_grid_wall"
    hit = m.__dict__.get(key)
    if hit is None:
        solid = m.occupied if unknown_free else (m.occupied | (m.unknown & ~specks(m.unknown, m.free, m.resolution)))
        hit = Grid(solid, m.resolution, m.origin, outside_solid=not unknown_free)
        object.__setattr__(m, key, hit)
    return hit


class GridWorld(World):
    """A ``World`` whose walls are a map's cells: the same interface the runner, sensors, radio and plants use
    (``space``, ``collisions``, ``step``, ``ranges``, ``attenuation_db``, ``gps_denied``), with no drawn walls."""

    def __init__(self, site: Site, grid: Grid, denied: tuple = (), stations: tuple[Station, ...] = ()) -> None:
        super().__init__((), denied, stations)
        self.site, self.grid = site, grid
        self.edge_count = 0
        self._tiles: dict[tuple[int, int], np.ndarray] | None = None  # tile -> its edges, world frame
        self._added: set[tuple[int, int]] = set()
        self._where: dict[int, tuple[int, int]] = {}  # body id -> the tile it was in at the last look
        self._countdown = 0
        # the walls enter the physics near the bodies that move, a tile at a time: a world asked only about its
        # radio (the validity check's mean link, a survey) never builds a segment, and a run on a large map
        # builds only the few thousand along its way
        self.step = self._step

    def draw_under(self, ax) -> None:
        """The map's cells under a plan view (the plots ask the world, so they need not know maps)."""
        self.grid.draw(ax)

    def _step(self, dt: float) -> None:
        self._countdown -= 1
        if self._countdown <= 0:  # a body crosses at most a few centimetres of a tile between two looks
            self._countdown = LOOK_EVERY
            for body in self.space.bodies:
                x, y = body.position
                key = (math.floor(x / TILE), math.floor(y / TILE))
                if self._where.get(id(body)) != key:
                    self._where[id(body)] = key
                    self._add_near(key)
        self.space.step(dt)

    def _add_near(self, key: tuple[int, int]) -> None:
        """The walls of the tiles around ``key`` (3 x 3: a body in the middle tile is at least a tile from any
        it has not got)."""
        if self._tiles is None:
            self._tiles = self._bucket()
        body = self.space.static_body
        shapes = []
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                tile = (key[0] + di, key[1] + dj)
                if tile in self._added:
                    continue
                self._added.add(tile)
                for a, b, c, d in self._tiles.get(tile, np.zeros((0, 4))).tolist():
                    seg = pymunk.Segment(body, (a, b), (c, d), SEGMENT_RADIUS)
                    seg.collision_type = WALL
                    seg.friction = 0.3
                    shapes.append(seg)
        if shapes:
            self.space.add(*shapes)
            self.edge_count += len(shapes)

    def _bucket(self) -> dict[tuple[int, int], np.ndarray]:
        """The map's edges in the world frame, by the tile of their midpoint (an edge is at most a map's width
        long: a long one sits in its midpoint's tile and is added with it; a body reaches it within a tile of
        that only if it is shorter than a tile, so long ones are split first)."""
        grid = self.grid
        e = grid.edges()
        n1, e1 = grid.world_of_uv(e[:, 0], e[:, 1])
        n2, e2 = grid.world_of_uv(e[:, 2], e[:, 3])
        seg = np.stack([n1, e1, n2, e2], axis=1)
        parts = np.maximum(1, np.ceil(np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) / (TILE / 2)))
        pieces = []
        for k in np.unique(parts).astype(int).tolist():  # split each long edge into pieces under half a tile
            sel = seg[parts == k]
            for j in range(k):
                a, b = j / k, (j + 1) / k
                d = sel[:, 2:] - sel[:, :2]
                pieces.append(np.concatenate([sel[:, :2] + d * a, sel[:, :2] + d * b], axis=1))
        seg = np.concatenate(pieces) if pieces else np.zeros((0, 4))
        ti = np.floor((seg[:, 0] + seg[:, 2]) / 2 / TILE).astype(np.int64)
        tj = np.floor((seg[:, 1] + seg[:, 3]) / 2 / TILE).astype(np.int64)
        order = np.lexsort((tj, ti))
        seg, ti, tj = seg[order], ti[order], tj[order]
        cut = np.flatnonzero((np.diff(ti) != 0) | (np.diff(tj) != 0)) + 1
        starts = np.concatenate([[0], cut])
        ends = np.concatenate([cut, [len(seg)]])
        return {(int(ti[a]), int(tj[a])): seg[a:b] for a, b in zip(starts.tolist(), ends.tolist(), strict=True)
                if b > a}

    def ranges(self, x: float, y: float, angles: np.ndarray, reach: float) -> np.ndarray:
        return self.grid.ranges(x, y, angles, reach)

    def attenuation_db(self, a: tuple[float, float], b: tuple[float, float]) -> float:
        if a == b:
            return 0.0
        runs, metres = self.grid.crossed(a, b)
        return self.site.wall_db * runs + self.site.wall_db_per_m * metres
