"""The simulated place: a pymunk space of static walls, GPS-denied zones and ground-station antennas.

Walls are real collision shapes (the robots are pymunk bodies) and also what the radio model looks through:
``attenuation_db`` sums the loss of every wall a line of sight crosses, using pymunk's segment queries.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pymunk

WALL, ROBOT = 1, 2
# A robot's shape is in a collision category of its own (it still collides with everything), so a line of sight
# can leave it out: the sight line ends at the robot, and pymunk calls back into Python for every shape it touches
ROBOT_CATEGORY = 0b10
ROBOT_FILTER = pymunk.ShapeFilter(categories=ROBOT_CATEGORY)
_SIGHT = pymunk.ShapeFilter(mask=pymunk.ShapeFilter.ALL_MASKS() ^ ROBOT_CATEGORY)


@dataclass(frozen=True)
class Wall:
    points: tuple[tuple[float, float], ...]
    thickness: float = 0.5
    attenuation_db: float = 20.0


@dataclass(frozen=True)
class Station:
    name: str
    x: float
    y: float
    sysid: int = 255
    power_dbm: float = 20.0


def _edges(poly: tuple[tuple[float, float], ...]) -> tuple[tuple[float, float, float, float], ...]:
    """The polygon's edges (x1, y1, x2, y2) in vertex order, closing edge last."""
    n = len(poly)
    return tuple((*poly[i], *poly[(i + 1) % n]) for i in range(n))


def _inside(x: float, y: float, edges: tuple[tuple[float, float, float, float], ...]) -> bool:
    """Whether (x, y) is inside the polygon of ``edges`` (worked out beforehand): the even-odd crossing test of a
    ray toward +x."""
    inside = False
    for x1, y1, x2, y2 in edges:
        if (y1 > y) != (y2 > y) and x < (x2 - x1) * (y - y1) / (y2 - y1) + x1:
            inside = not inside
    return inside


def _capsules(walls: tuple[Wall, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The walls' collision capsules as a range sensor sees them: each segment's two faces (px, py, ex, ey: a
    start and its extent, offset by half the thickness either side) and its two round ends (cx, cy, radius)."""
    faces, ends = [], []
    for wall in walls:
        h = wall.thickness / 2
        for a, b in zip(wall.points[:-1], wall.points[1:], strict=True):
            ex, ey = b[0] - a[0], b[1] - a[1]
            n = (ex * ex + ey * ey) ** 0.5
            if n < 1e-12:
                ends.append((a[0], a[1], h))
                continue
            nx, ny = -ey / n * h, ex / n * h
            faces.append((a[0] + nx, a[1] + ny, ex, ey))
            faces.append((a[0] - nx, a[1] - ny, ex, ey))
            ends.append((a[0], a[1], h))
            ends.append((b[0], b[1], h))
    return np.array(faces, dtype=float).reshape(-1, 4), np.array(ends, dtype=float).reshape(-1, 3)


class World:
    def __init__(self, walls: tuple[Wall, ...], denied: tuple[tuple[tuple[float, float], ...], ...] = (),
                 stations: tuple[Station, ...] = ()) -> None:
        self.walls = walls
        self.denied = denied
        self._denied_edges = tuple(_edges(poly) for poly in denied)  # the sensors ask at every fix time
        self.stations = stations
        self.space = pymunk.Space()
        self.space.iterations = 10
        self.collisions = 0
        self._touching = 0
        for wall in walls:
            for a, b in zip(wall.points[:-1], wall.points[1:], strict=True):
                seg = pymunk.Segment(self.space.static_body, a, b, wall.thickness / 2)
                seg.collision_type = WALL
                seg.friction = 0.3
                seg.attenuation_db = wall.attenuation_db  # type: ignore[attr-defined]
                self.space.add(seg)
        self._faces, self._ends = _capsules(walls)  # what a range sensor's beams can hit
        self.space.on_collision(ROBOT, WALL, begin=self._begin, separate=self._separate)
        self.step: Callable[[float], None] = self.space.step  # one physics step of dt seconds (every tick)

    def _begin(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: object) -> None:
        if self._touching == 0:
            self.collisions += 1
        self._touching += 1

    def _separate(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: object) -> None:
        self._touching = max(0, self._touching - 1)

    def draw_under(self, ax) -> None:
        """What a plan view draws under the walls: nothing for a drawn world (a map world draws its cells)."""

    def gps_denied(self, x: float, y: float) -> bool:
        for edges in self._denied_edges:  # noqa: SIM110 - a loop, not any() over a generator, at every fix time
            if _inside(x, y, edges):
                return True
        return False

    def ranges(self, x: float, y: float, angles: np.ndarray, reach: float) -> np.ndarray:
        """Distance from (x, y) along each world-frame angle (rad, from north toward east) to the first wall, as
        the walls' collision shapes have it (capsules: a segment thickened by half the wall's thickness); inf where
        nothing lies within ``reach``. All beams against all walls at once (a scan is a few dozen beams)."""
        dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
        best = np.full(len(angles), np.inf)
        if len(self._faces):
            px, py, ex, ey = (self._faces[:, k][None, :] for k in range(4))
            wx, wy = px - x, py - y
            den = dx * ey - dy * ex
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (wx * ey - wy * ex) / den
                u = (wx * dy - wy * dx) / den
            ok = (np.abs(den) > 1e-12) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
            best = np.minimum(best, np.where(ok, t, np.inf).min(axis=1))
        if len(self._ends):
            cx, cy, h = (self._ends[:, k][None, :] for k in range(3))
            wx, wy = cx - x, cy - y
            along = dx * wx + dy * wy
            disc = h * h - (wx * wx + wy * wy) + along * along
            with np.errstate(invalid="ignore"):
                t = along - np.sqrt(disc)
            ok = (disc >= 0.0) & (t >= 0.0)
            best = np.minimum(best, np.where(ok, t, np.inf).min(axis=1))
        return np.where(best <= reach, best, np.inf)

    def attenuation_db(self, a: tuple[float, float], b: tuple[float, float]) -> float:
        """Total wall loss along the straight line a -> b (each wall segment crossed counts once)."""
        if a == b:
            return 0.0
        hits = self.space.segment_query(a, b, 0.0, _SIGHT)  # walls only (a robot adds no loss)
        return float(sum(getattr(h.shape, "attenuation_db", 0.0) for h in hits if h.shape is not None))
