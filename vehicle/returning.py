"""Return planning (docs/architecture.md §6): where to go back to, and the route there. Pure functions of the trail.

The return target and route are recomputed from the trail at the moment a return block starts (and on a replan);
the auto-return service then drives the route with the navigator under a sublease of its block.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from vehicle.trail import Trail

SPEED_RANGE = (0.3, 2.0)  # m/s: stretch speeds worth copying (a crawl is a pause; beyond the teleop limit, a glitch)
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
    speeds: np.ndarray | None = None  # per point: the speed driven outbound on the stretch leaving it (m/s)
    onward: Route | None = None  # LINK after a loss: the trail from the target back to its start (dead zones)

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
    return _retrace(trail, start, goal)[0]


def _retrace(trail: Trail, start: tuple[float, float], goal: int,
             first: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``retrace`` from kept index ``first`` (default: the newest), with, per route point, the kept index whose
    outbound stretch (from index - 1 to index) the route drives next (-1: not known)."""
    pts = trail.points()
    out = [np.asarray(start, dtype=float)]
    idx = [-1]
    i = len(pts) - 1 if first is None else first
    while i > goal:
        p = pts[i]
        out.append(p)
        idx.append(i)
        s = trail.shortcut(i)
        if s >= 0 and s >= goal and s + 1 < i:
            # cross to the nearest point of the older segment, then carry on backwards from its start
            out.append(_closest_on_segment(p, pts[s], pts[s + 1]))
            idx.append(s + 1)
            i = s
            continue
        i -= 1
    out.append(pts[goal])
    idx.append(goal)
    route = np.array(out)
    keep = np.ones(len(route), dtype=bool)
    keep[1:] = np.hypot(*np.diff(route, axis=0).T) > 1e-9
    return route[keep], np.array(idx)[keep]


def outbound_speeds(trail: Trail, idx: np.ndarray) -> np.ndarray:
    """Per route point, the speed the robot drove the trail stretch it is about to retrace (RTL_SPEED=0), from
    the crumbs' times; a point with no stretch of its own takes the next one's (nan if none is known)."""
    pts, t = trail.points(), trail.times()
    seg = np.full(len(pts), np.nan)
    if len(pts) >= 2:
        dt = np.diff(t)
        dist = np.hypot(*np.diff(pts, axis=0).T)
        with np.errstate(divide="ignore", invalid="ignore"):
            seg[1:] = np.where(dt > 1e-6, dist / np.where(dt > 1e-6, dt, 1.0), np.nan)
    v = np.array([seg[i] if 1 <= i < len(seg) else np.nan for i in idx])
    # a stretch slower than a crawl held a pause (or joins crumbs of different drives), one faster than the
    # robot can go is an estimation glitch: neither is a pace to copy, the neighbours' is
    v[(v < SPEED_RANGE[0]) | (v > SPEED_RANGE[1])] = np.nan
    for k in range(len(v) - 2, -1, -1):  # the start and the trail's first point take their neighbour's stretch
        if np.isnan(v[k]):
            v[k] = v[k + 1]
    for k in range(1, len(v)):
        if np.isnan(v[k]):
            v[k] = v[k - 1]
    return v


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


def _head(pts: np.ndarray, dist: float) -> list[np.ndarray]:
    """The points of polyline ``pts`` after its first, up to ``dist`` metres along it (the last one cut there)."""
    out: list[np.ndarray] = []
    left = dist
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        seg = float(np.hypot(*(b - a)))
        if seg >= left:
            if seg > 1e-9:
                out.append(a + (b - a) * (left / seg))
            break
        out.append(b)
        left -= seg
    return out


def plan_route(trail: Trail, start: tuple[float, float], target: Target, max_displacement: float,
               link_lost: bool, heading: float = 0.0, overshoot: float = 0.0) -> Route:
    """The whole planning step: target, retraced route, displacement bound.

    ``overshoot`` extends a LINK route that far past the target crumb, further back along the trail: the
    navigator counts as arrived within RTL_ARRIVE_R of the route's end, and a return that stops that short of
    the last place the operator was heard stops on the fringe of coverage, not inside it.

    A LINK route after a loss also carries ``onward``: the trail from the target back to its start, which the
    service follows when the target turns out to be a dead zone (docs/architecture.md §6).
    """
    if target is Target.HEADING:
        s = np.asarray(start, dtype=float)
        end = s + max_displacement * np.array([math.cos(heading), math.sin(heading)])
        return Route(np.array([s, end]), (float(end[0]), float(end[1])), -1, True)
    good = trail.link_good()
    goal = target_index(good, target, link_lost)
    if goal < 0:
        s = np.asarray(start, dtype=float)
        return Route(np.array([s]), None, -1, False)
    full, idx = _retrace(trail, start, goal)
    speeds = outbound_speeds(trail, idx)
    gx, gy = full[-1]
    onward = None
    if target is Target.LINK and link_lost:
        # further back means along the retraced trail (shortcuts taken), not down the list of crumbs: the newest
        # of those may have been laid by an earlier return, heading the other way
        o_pts, o_idx = _retrace(trail, (float(gx), float(gy)), 0, first=goal)
        onward = Route(o_pts, (float(o_pts[-1, 0]), float(o_pts[-1, 1])), 0, False, outbound_speeds(trail, o_idx))
        extra = _head(o_pts, overshoot) if overshoot > 0 else []
        if extra:
            full = np.vstack([full, extra])
            speeds = np.concatenate([speeds, np.full(len(extra), speeds[-1])])
    pts, cut = truncate(full, start, max_displacement)
    return Route(pts, (float(gx), float(gy)), goal, cut, speeds[:len(pts)], onward)


def continue_from(route: Route, at: tuple[float, float], search: float) -> Route:
    """``route`` picked up at the point nearest ``at`` within its first ``search`` metres: where a return that
    overshot a dead-zone target joins the trail further back."""
    pts = route.points
    if len(pts) < 2:
        return Route(np.array([at]), route.target, route.target_index, route.truncated, None, None)
    p = np.asarray(at, dtype=float)
    best, best_d, walked = (0, pts[0]), math.inf, 0.0
    for k in range(len(pts) - 1):
        q = _closest_on_segment(p, pts[k], pts[k + 1])
        d = float(np.hypot(*(q - p)))
        if d < best_d:
            best, best_d = (k, q), d
        walked += float(np.hypot(*(pts[k + 1] - pts[k])))
        if walked > search:
            break
    k, q = best
    out = np.vstack([p, q, pts[k + 1:]])
    sp = None
    if route.speeds is not None:
        sp = np.concatenate([[route.speeds[k], route.speeds[k]], route.speeds[k + 1:]])
    keep = np.ones(len(out), dtype=bool)
    keep[1:] = np.hypot(*np.diff(out, axis=0).T) > 1e-9
    return Route(out[keep], route.target, route.target_index, route.truncated,
                 None if sp is None else sp[keep], None)
