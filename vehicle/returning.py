"""Return planning (DESIGN §6): where to go back to, and the route there. Pure functions of the trail.

The return target and route are recomputed from the trail at the moment a return block starts (and on a replan);
the auto-return service then drives the route with the navigator under a sublease of its block.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from vehicle.trail import Trail

LINK_TAG_LAG_S = 1.0  # the link-quality estimate behind a crumb's tag averages over about this long


class Target(enum.IntEnum):
    """RTL_TARGET."""

    LINK = 0
    ORIGIN = 1
    HEADING = 2


@dataclass(frozen=True)
class Route:
    points: np.ndarray  # (n, 2) from the return start to the end of the route
    target: tuple[float, float] | None  # the chosen return target (may lie beyond a truncated route)
    target_index: int  # kept trail index of the target (-1 for HEADING)
    truncated: bool  # cut where it first leaves the max-displacement circle (FIG. 4C)

    @property
    def length(self) -> float:
        return polyline_length(self.points)

    @property
    def end(self) -> tuple[float, float]:
        return float(self.points[-1, 0]), float(self.points[-1, 1])


def polyline_length(points: np.ndarray) -> float:
    if len(points) < 2:
        return 0.0
    d = np.diff(points, axis=0)
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def target_index(link_good: np.ndarray, target: Target, link_lost: bool) -> int:
    """Index into the trail of the return target.

    LINK: going back along the trail, the nearest crumb where the link was good before the current loss (claim 8).
    If the link has not been lost (an operator-commanded return) or was never good, the trail's start.
    ORIGIN: the trail's start.
    """
    n = len(link_good)
    if n == 0:
        return -1
    if target is Target.ORIGIN or not link_lost:
        return 0
    good = np.flatnonzero(link_good)
    if len(good) == 0:
        return 0
    return int(good[-1])


def _closest_on_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    L2 = float(ab @ ab)
    if L2 < 1e-18:
        return a.copy()
    u = min(1.0, max(0.0, float((p - a) @ ab) / L2))
    return a + u * ab


def retrace(trail: Trail, start: tuple[float, float], goal: int) -> np.ndarray:
    """The trail reversed from ``start`` back to kept index ``goal``, loops pruned by the trail's shortcuts.

    A shortcut is taken only if it does not jump past the goal, so pruning never changes the target.
    """
    pts = trail.points()
    out = [np.asarray(start, dtype=float)]
    i = len(pts) - 1
    while i > goal:
        p = pts[i]
        out.append(p)
        s = trail.shortcut(i)
        if s >= 0 and s >= goal and s + 1 < i:
            # cross to the nearest point of the older segment, then carry on backwards from its start
            out.append(_closest_on_segment(p, pts[s], pts[s + 1]))
            i = s
            continue
        i -= 1
    out.append(pts[goal])
    route = np.array(out)
    keep = np.ones(len(route), dtype=bool)
    keep[1:] = np.hypot(*np.diff(route, axis=0).T) > 1e-9
    return route[keep]


def truncate(route: np.ndarray, center: tuple[float, float], radius: float) -> tuple[np.ndarray, bool]:
    """Cut the route where it first leaves the circle (FIG. 4C: stop on the boundary)."""
    c = np.asarray(center, dtype=float)
    out = [route[0]]
    for a, b in zip(route[:-1], route[1:], strict=True):
        if np.hypot(*(b - c)) <= radius:
            out.append(b)
            continue
        # solve |a + u (b - a) - c| = radius for the first u in [0, 1]
        d, f = b - a, a - c
        A, B, C = float(d @ d), 2 * float(f @ d), float(f @ f) - radius * radius
        disc = max(0.0, B * B - 4 * A * C)
        u = (-B + math.sqrt(disc)) / (2 * A) if A > 0 else 0.0
        out.append(a + max(0.0, min(1.0, u)) * d)
        return np.array(out), True
    return np.array(out), False


def _beyond(pts: np.ndarray, goal: int, dist: float) -> list[np.ndarray]:
    """Points continuing from kept point ``goal`` back toward the trail's start for ``dist`` metres."""
    out: list[np.ndarray] = []
    i, left = goal, dist
    while i > 0 and left > 1e-9:
        a, b = pts[i], pts[i - 1]
        seg = float(np.hypot(*(b - a)))
        if seg >= left:
            out.append(a + (b - a) * (left / seg))
            break
        out.append(b)
        left -= seg
        i -= 1
    return out


def plan_route(trail: Trail, start: tuple[float, float], target: Target, max_displacement: float,
               link_lost: bool, heading: float = 0.0, overshoot: float = 0.0) -> Route:
    """The whole planning step: target, retraced route, displacement bound.

    ``overshoot`` extends a LINK route that far past the target crumb, further back along the trail: the
    navigator counts as arrived within RTL_ARRIVE_R of the route's end, and a return that stops that short of
    the last place the operator was heard stops on the fringe of coverage, not inside it.
    """
    """The whole planning step: target, retraced route, displacement bound."""
    if target is Target.HEADING:
        s = np.asarray(start, dtype=float)
        end = s + max_displacement * np.array([math.cos(heading), math.sin(heading)])
        return Route(np.array([s, end]), (float(end[0]), float(end[1])), -1, True)
    good = trail.link_good()
    goal = target_index(good, target, link_lost)
    if goal < 0:
        s = np.asarray(start, dtype=float)
        return Route(np.array([s]), None, -1, False)
    full = retrace(trail, start, goal)
    gx, gy = full[-1]
    if overshoot > 0 and target is Target.LINK and link_lost:
        extra = _beyond(trail.points(), goal, overshoot)
        if extra:
            full = np.vstack([full, extra])
    pts, cut = truncate(full, start, max_displacement)
    return Route(pts, (float(gx), float(gy)), goal, cut)
