"""Plane geometry the world families share: corridors as offset polylines, distances between segments.

Families describe a place by its centre lines (a drift, a pipe, a corridor) and a clear width; the walls are the
centre line offset to either side by half the clear width plus half the wall's thickness, so the *clear* width
between the walls' faces is what the family drew (a wall is a capsule: a segment thickened by half its thickness,
as ``sim.world`` builds it). Joins are mitred, like a drift driven round a bend.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

Point = tuple[float, float]


def bent_line(rng: np.random.Generator, legs: int, bend_deg: tuple[float, float],
              leg_m: tuple[float, float]) -> list[Point]:
    """A centre line from (0, 0) heading north: ``legs`` straight legs of ``leg_m`` metres, each bend ``bend_deg``
    degrees left or right (``rng``: a numpy Generator), the heading kept within 90 degrees of straight in, so the
    drive never folds back into itself (a culvert's pipe runs, a mine's drifts)."""
    points, angle = [(0.0, 0.0)], 0.0
    for k in range(legs):
        if k:
            turn = math.radians(float(rng.uniform(*bend_deg)))
            sign = 1.0 if rng.random() < 0.5 else -1.0
            if abs(angle + sign * turn) > math.pi / 2 + 1e-9:
                sign = -sign
            angle += sign * turn
        points.append(add(points[-1], heading(angle), float(rng.uniform(*leg_m))))
    return points


def unit(a: Point, b: Point) -> Point:
    """The unit vector from a toward b."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = math.hypot(dx, dy)
    return dx / n, dy / n


def heading(angle: float) -> Point:
    """The unit vector of ``angle`` (radians from +x, north, toward +y, east)."""
    return math.cos(angle), math.sin(angle)


def add(p: Point, v: Point, k: float = 1.0) -> Point:
    return p[0] + k * v[0], p[1] + k * v[1]


def left(v: Point) -> Point:
    """``v`` turned a quarter turn toward +y."""
    return -v[1], v[0]


def offset(line: Sequence[Point], d: float) -> list[Point]:
    """``line`` moved ``d`` to its left (negative: right), mitred at every interior vertex."""
    out = []
    for i, p in enumerate(line):
        normals = []
        if i > 0:
            normals.append(left(unit(line[i - 1], p)))
        if i < len(line) - 1:
            normals.append(left(unit(p, line[i + 1])))
        nx, ny = sum(n[0] for n in normals), sum(n[1] for n in normals)
        k = math.hypot(nx, ny)
        nx, ny = nx / k, ny / k
        cos_half = nx * normals[0][0] + ny * normals[0][1]  # the mitre grows by 1 / cos(half the turn)
        out.append((p[0] + nx * d / cos_half, p[1] + ny * d / cos_half))
    return out


def length(line: Sequence[Point]) -> float:
    return sum(math.dist(a, b) for a, b in zip(line[:-1], line[1:], strict=True))


def along(line: Sequence[Point], s: float) -> Point:
    """The point ``s`` metres along ``line`` (its end beyond its length)."""
    for a, b in zip(line[:-1], line[1:], strict=True):
        d = math.dist(a, b)
        if s <= d:
            return add(a, unit(a, b), s)
        s -= d
    return line[-1]


def cut(line: Sequence[Point], s: float) -> list[Point]:
    """``line`` up to ``s`` metres along it."""
    out, walked = [line[0]], 0.0
    for a, b in zip(line[:-1], line[1:], strict=True):
        d = math.dist(a, b)
        if walked + d >= s:
            out.append(add(a, unit(a, b), s - walked))
            return out
        out.append(b)
        walked += d
    return out


def point_segment(p: Point, a: Point, b: Point) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    L2 = dx * dx + dy * dy
    u = 0.0 if L2 == 0 else max(0.0, min(1.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / L2))
    return math.hypot(p[0] - a[0] - u * dx, p[1] - a[1] - u * dy)


def _cross(o: Point, a: Point, b: Point) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def segments_cross(a: Point, b: Point, c: Point, d: Point) -> bool:
    """Whether segments ab and cd properly cross (touching ends count as crossing)."""
    d1, d2, d3, d4 = _cross(c, d, a), _cross(c, d, b), _cross(a, b, c), _cross(a, b, d)
    return (d1 * d2 <= 0) and (d3 * d4 <= 0) and not (d1 == d2 == d3 == d4 == 0)


def segment_distance(a: Point, b: Point, c: Point, d: Point) -> float:
    """The least distance between segments ab and cd (0 where they cross)."""
    if segments_cross(a, b, c, d):
        return 0.0
    return min(point_segment(a, c, d), point_segment(b, c, d), point_segment(c, a, b), point_segment(d, a, b))


def polyline_distance(p: Sequence[Point], q: Sequence[Point]) -> float:
    """The least distance between two polylines (a single point counts as a line of one point)."""
    ps = list(zip(p[:-1], p[1:], strict=True)) or [(p[0], p[0])]
    qs = list(zip(q[:-1], q[1:], strict=True)) or [(q[0], q[0])]
    return min(segment_distance(a, b, c, d) for a, b in ps for c, d in qs)
