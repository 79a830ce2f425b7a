"""Return planning (docs/architecture.md §6): where to go back to, and the route there. Pure functions of the trail.

The return target and route are recomputed from the trail at the moment a return block starts (and on a replan);
the auto-return service then drives the route with the navigator under a sublease of its block.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from vehicle.clearance import FreeSpace, keep_clear, shortcut
from vehicle.linkmap import LinkMap
from vehicle.trail import Trail

SPEED_RANGE = (0.3, 2.0)  # m/s: stretch speeds worth copying (a crawl is a pause; beyond the teleop limit, a glitch)
PACE_WINDOW_M = 2.0  # m of path either side whose fastest stretch a return may drive at
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
    way: Way | None = None  # the whole way back this route was cut from: the next block of a chain resumes it
    by_map: bool = False  # the target is the nearest place the link map says reliably holds

    @property
    def length(self) -> float:
        return polyline_length(self.points)

    @property
    def end(self) -> tuple[float, float]:
        return float(self.points[-1, 0]), float(self.points[-1, 1])


@dataclass(frozen=True)
class Way:
    """The whole way back along the trail from where a return began: the trail retraced (loops pruned) to its start,
    with the outbound speed of each stretch and how far along it the crumbs' link target lies.

    Consecutive blocks of one return chain resume the way where the robot has got to on it, instead of retracing
    the trail again: the newest crumbs are the previous block's own, laid heading back, and retracing them would
    drive the robot forward over the stretch it had just returned along (issue 21: 7.4 m of path for 2.8 m)."""

    points: np.ndarray
    speeds: np.ndarray
    goal: float  # metres along ``points`` to the crumb target (the last link-good crumb before the loss)
    heard: float = 0.0  # metres along ``points`` to where the last stretch driven with the link ended (0: none)

    @property
    def length(self) -> float:
        return polyline_length(self.points)

    def resumed(self, at: tuple[float, float], search: float) -> Way:
        """The rest of the way from the point nearest ``at`` within its first ``search`` metres."""
        pts = self.points
        if len(pts) < 2:
            return Way(np.array([at], dtype=float), self.speeds[:1], 0.0)
        p = np.asarray(at, dtype=float)
        best, best_d, best_s, walked = (0, pts[0]), math.inf, 0.0, 0.0
        for k in range(len(pts) - 1):
            q = _closest_on_segment(p, pts[k], pts[k + 1])
            d = float(np.hypot(*(q - p)))
            if d < best_d:
                best, best_d, best_s = (k, q), d, walked + float(np.hypot(*(q - pts[k])))
            walked += float(np.hypot(*(pts[k + 1] - pts[k])))
            if walked > search:
                break
        k, q = best
        out = np.vstack([p, q, pts[k + 1:]])
        sp = np.concatenate([[self.speeds[k], self.speeds[k]], self.speeds[k + 1:]])
        keep = np.ones(len(out), dtype=bool)
        keep[1:] = np.hypot(*np.diff(out, axis=0).T) > 1e-9

        def still_ahead(s: float) -> float:  # a distance along the old way, from the robot on the new one
            return max(0.0, s - best_s) + (best_d if s > best_s else 0.0)

        return Way(out[keep], sp[keep], still_ahead(self.goal), still_ahead(self.heard))


def _cut(pts: np.ndarray, at: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Polyline ``pts`` split ``at`` metres along it: (head up to the cut, tail from it, index of the segment cut)."""
    walked = 0.0
    for k in range(len(pts) - 1):
        seg = float(np.hypot(*(pts[k + 1] - pts[k])))
        if walked + seg >= at:
            u = (at - walked) / seg if seg > 1e-12 else 0.0
            c = pts[k] + u * (pts[k + 1] - pts[k])
            return np.vstack([pts[: k + 1], c]), np.vstack([c, pts[k + 1:]]), k
        walked += seg
    return pts.copy(), pts[-1:].copy(), max(0, len(pts) - 2)


def _along(pts: np.ndarray, k: int, u: float) -> float:
    """Metres along polyline ``pts`` to fraction ``u`` of segment ``k``."""
    d = np.hypot(*np.diff(pts[: k + 2], axis=0).T) if len(pts) > 1 else np.zeros(0)
    return float(d[:k].sum() + u * (d[k] if k < len(d) else 0.0))


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


def heard_stretch(link_good: np.ndarray, goal: int) -> int:
    """Index of the crumb where the last stretch driven with the link ended, at or before ``goal``: the newest
    link-good crumb whose predecessor was link-good too (-1: none). A lone link-good crumb among lost ones is a
    moment's packet in a dead place, not a way the link holds along (a packet heard deep in a room whose link came
    back only at the door; docs/evidence.md, "The measurements behind the vehicle's code")."""
    good = np.asarray(link_good[: goal + 1], dtype=bool)
    both = np.flatnonzero(good[1:] & good[:-1])
    return int(both[-1]) + 1 if len(both) else -1


def _heard_along(pts: np.ndarray, idx: np.ndarray, crumb: int) -> float:
    """Metres along the way ``pts`` (with per-point kept index ``idx``) to kept crumb ``crumb`` (0: not on it)."""
    if crumb < 0:
        return 0.0
    at = np.flatnonzero(idx == crumb)
    if len(at) == 0:
        return 0.0
    return polyline_length(pts[: int(at[0]) + 1])


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
    """Per route point, the speed the robot drove the trail stretch it is about to retrace (RTL_SPEED=0): the
    pace its crumbs were laid at, or, where the crumbs carry none, the stretch's length over its time; a point
    with no stretch of its own takes the next one's (nan if none is known).

    The pace is the fastest the robot went on the stretch, not its average: a stretch's time also holds the
    turns on the spot at its ends and the stutter of teleop through a fading link, which are not a pace to drive
    back at (a return that copied them fell behind every baseline), while a stretch the operator drove slowly
    from end to end still has a slow pace."""
    pts, t, pace = trail.points(), trail.times(), trail.paces()
    seg = np.full(len(pts), np.nan)
    if len(pts) >= 2:
        dt = np.diff(t)
        dist = np.hypot(*np.diff(pts, axis=0).T)
        with np.errstate(divide="ignore", invalid="ignore"):
            seg[1:] = np.where(dt > 1e-6, dist / np.where(dt > 1e-6, dt, 1.0), np.nan)
        # a stretch's average slower than a crawl held a pause (or joins crumbs of different drives), one faster
        # than the robot can go is an estimation glitch: neither is a pace to copy, the neighbours' is
        seg[(seg < SPEED_RANGE[0]) | (seg > SPEED_RANGE[1])] = np.nan
        # a measured pace is the odometry's, smoothed: at the robot's top speed its noise rises past the limit
        seg[1:] = np.where(np.isfinite(pace[1:]), np.minimum(pace[1:], SPEED_RANGE[1]), seg[1:])
        seg[seg < SPEED_RANGE[0]] = np.nan
    v = np.array([seg[i] if 1 <= i < len(seg) else np.nan for i in idx])
    for k in range(len(v) - 2, -1, -1):  # the start and the trail's first point take their neighbour's stretch
        if np.isnan(v[k]):
            v[k] = v[k + 1]
    for k in range(1, len(v)):
        if np.isnan(v[k]):
            v[k] = v[k - 1]
    return v


def _neighbourhood_max(route: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Each point's speed raised to the fastest within PACE_WINDOW_M of path either side: a stretch of a few
    crumbs where the robot was slowing down (the coast to a stop where the link went, the last metre of a
    simplified stretch) takes the pace of the driving around it, which the robot kept there a moment before."""
    if len(v) < 2:
        return v
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(route, axis=0).T))])
    lo = np.searchsorted(s, s - PACE_WINDOW_M, side="left")
    hi = np.searchsorted(s, s + PACE_WINDOW_M, side="right")
    return np.array([v[a:b].max() for a, b in zip(lo, hi, strict=True)])


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


def plan_route(trail: Trail, start: tuple[float, float], target: Target, max_displacement: float,
               link_lost: bool, heading: float = 0.0, overshoot: float = 0.0, linkmap: LinkMap | None = None,
               resume: Way | None = None, map_depth: float = 0.0, map_seek: float = 0.0,
               free: FreeSpace | None = None, clearance: float = 0.0) -> Route:
    """The whole planning step: target, retraced route, displacement bound.

    The way back is the trail retraced from ``start`` to its first crumb (loops pruned), or ``resume``, the way an
    earlier block of the same chain was on, picked up where the robot is: a chain never drives a stretch twice.

    LINK after a loss: the target is the nearest place back along the way, at or beyond the last link-good crumb,
    that ``linkmap`` says reliably holds the link, ``map_depth`` metres into it (a place on the fringe of a good
    cell is still the fringe) but no further than halfway to a place seen to fail beyond it; with no such place, the
    last link-good crumb itself, ``overshoot`` metres further back (the navigator counts as arrived within
    RTL_ARRIVE_R of the route's end, and the tag lags the link). The route also carries ``onward``: the way beyond
    the target, which the service follows when the target turns out to be a dead zone (docs/architecture.md §6): the
    crumb target's whole way on; the map's place's way into the next stretch where the link held, or ``map_seek``
    metres (LNK_MAP_SEEK). Otherwise (ORIGIN, or a return commanded over a good link): the trail's start. The route
    is cut where it first leaves the displacement circle (FIG. 4C).
    """
    if target is Target.HEADING:
        s = np.asarray(start, dtype=float)
        end = s + max_displacement * np.array([math.cos(heading), math.sin(heading)])
        return Route(np.array([s, end]), (float(end[0]), float(end[1])), -1, True)
    way, goal = (resume, -1) if resume is not None else _retraced_way(trail, start, target, link_lost)
    if way is None:
        s = np.asarray(start, dtype=float)
        return Route(np.array([s]), None, -1, False)
    lost_link = target is Target.LINK and link_lost
    total = way.length
    at, by_map, extra, onward_to = _stop_along(way, lost_link, linkmap, overshoot, map_depth, map_seek)
    at = min(at, total)
    head, _, k = _cut(way.points, at)
    gx, gy = float(head[-1, 0]), float(head[-1, 1])
    full, tail, k2 = _cut(way.points, min(total, at + extra))
    # a point's speed is that of the stretch leaving it: the cut point drives on at its segment's
    speeds = np.concatenate([way.speeds[: k2 + 1], [way.speeds[k2]]])
    onward = _onward(way, at, k, onward_to, free, clearance) if lost_link and onward_to > at + extra else None
    keep = np.ones(len(full), dtype=bool)
    keep[1:] = np.hypot(*np.diff(full, axis=0).T) > 1e-9
    full, speeds = full[keep], speeds[: len(keep)][keep]
    # the corners the range sensor saw clear are cut (after a loss, only up to the stretch last driven with the
    # link), and the route from there is pushed clear of what it saw occupied, as far as the seen free space allows
    # (vehicle/clearance.py); the way itself stays the crumbs
    full, speeds, heard_at = _cut_corners(full, speeds, way.heard if lost_link else 0.0, free, clearance)
    if heard_at < len(full) - 1:
        kept, kept_speeds = keep_clear(full[heard_at:], speeds[heard_at:], free, clearance)
        full, speeds = np.vstack([full[:heard_at], kept]), np.concatenate([speeds[:heard_at], kept_speeds])
    pts, cut = truncate(full, start, max_displacement)
    return Route(pts, (gx, gy), goal if goal >= 0 else -1, cut, speeds[: len(pts)], onward, way, by_map)


def _retraced_way(trail: Trail, start: tuple[float, float], target: Target,
                  link_lost: bool) -> tuple[Way | None, int]:
    """(the way back along the trail from ``start``, the crumb target's index): to the crumb target (shortcuts
    never jump past it), then on from it to the trail's start; (None, goal) when there is no crumb target."""
    good = trail.link_good()
    goal = target_index(good, target, link_lost)
    if goal < 0:
        return None, goal
    pts, idx = _retrace(trail, start, goal)
    at_goal = polyline_length(pts)
    if goal > 0:
        more, more_idx = _retrace(trail, (float(pts[-1, 0]), float(pts[-1, 1])), 0, first=goal)
        pts, idx = np.vstack([pts, more[1:]]), np.concatenate([idx, more_idx[1:]])
    return Way(pts, _neighbourhood_max(pts, outbound_speeds(trail, idx)), at_goal,
               _heard_along(pts, idx, heard_stretch(good, goal))), goal


def _stop_along(way: Way, lost_link: bool, linkmap: LinkMap | None, overshoot: float, map_depth: float,
                map_seek: float) -> tuple[float, bool, float, float]:
    """Where along ``way`` the return stops: (metres along, whether the link map chose it, how much further it
    drives past it, how far along a block that arrives with the link still down may go on)."""
    total = way.length
    if not lost_link:
        return total, False, 0.0, total
    if linkmap is None:
        return way.goal, False, overshoot, total
    hit = linkmap.first_reliable(way.points, skip=way.goal)
    if hit is None:
        return way.goal, False, overshoot, total
    at = _along(way.points, *hit)
    # into the place, but no further than halfway to where the way next meets a place the link was seen to fail (a
    # null, a loop back through a dead stretch): that is a fringe like the one it entered by (an unvisited cell
    # beside the trail is not: a trail runs along cell edges)
    gap = linkmap.first_reliable(way.points, skip=at, poor=True)
    extra = map_depth if gap is None else min(map_depth, 0.5 * (_along(way.points, *gap) - at))
    return at, True, extra, _next_stretch(linkmap, way.points, at, gap, map_depth, map_seek)


def _onward(way: Way, at: float, k: int, onward_to: float, free: FreeSpace | None, clearance: float) -> Route:
    """The way on beyond the stop (the ``k``-th segment holds it) to ``onward_to``, kept clear of what the range
    sensor saw occupied: what a block follows when its target turns out to be a dead zone."""
    o_pts = _cut(_cut(way.points, onward_to)[0], at)[1]
    o_speeds = np.concatenate([[way.speeds[k]], way.speeds[k + 1:]])[: len(o_pts)]
    o_pts, o_speeds = keep_clear(o_pts, o_speeds, free, clearance)
    return Route(o_pts, (float(o_pts[-1, 0]), float(o_pts[-1, 1])), 0, False, o_speeds)


def _cut_corners(pts: np.ndarray, speeds: np.ndarray, heard: float, free: FreeSpace | None,
                 clearance: float) -> tuple[np.ndarray, np.ndarray, int]:
    """``pts`` with the corners cut that ``free`` shows clear (``vehicle.clearance.shortcut``) up to the end of
    the last stretch the robot drove with the link, ``heard`` metres along, and the crumbs themselves from there
    on (``heard`` 0: none ahead, every corner may be cut); and the index in the result of that stretch's end, from
    which on the route is also kept clear of what the sensor saw occupied (0: all of it).

    The link comes back first on the stretch where it was last heard, so the route drives that stretch as it was
    driven: a straight line from a dead end to a place beyond trades the known way to the link for an unknown one,
    and reached the link later where it was tried. Before that stretch the robot is in the dead place it drove
    into, where a cut across seen free space loses nothing.

    Up to that stretch's end the route is not pushed off the walls either (``keep_clear``): the operator drove the
    dead end along a wall, the link returns along those crumbs, and a route 0.5 m off them is a route into the
    drift's radio shadow. The body is kept off those walls where it matters, in the body frame, whatever the
    estimate's error (``vehicle.standoff``). The figures behind each sentence: docs/evidence.md, "The measurements
    behind the vehicle's code"."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    if heard <= 0.0 or heard >= cum[-1] - 1e-6:  # no such stretch, or the route ends on it: every corner
        cut, cut_speeds = shortcut(pts, speeds, free, clearance)
        return cut, cut_speeds, 0 if heard <= 0.0 else len(cut) - 1
    j = int(np.searchsorted(cum, heard + 1e-6, side="right")) - 1  # the last point at or before it
    if j <= 0:
        return pts, speeds, 0
    a_pts, a_sp = shortcut(pts[: j + 1], speeds[: j + 1], free, clearance)
    return np.vstack([a_pts, pts[j + 1:]]), np.concatenate([a_sp[:-1], speeds[j:]]), len(a_pts) - 1


def _next_stretch(linkmap: LinkMap, pts: np.ndarray, at: float, gap: tuple[int, float] | None, depth: float,
                  seek: float) -> float:
    """Metres along ``pts`` a return may go on to when it reached the place the map vouched for (``at``) and the
    link is still down: into the next separate stretch the map says held the link (past ``gap``, the first place
    beyond ``at`` where it was seen to fail), or, with none, ``seek`` metres on (LNK_MAP_SEEK; 0: it stays). Going
    on inside one good stretch does not help: the place held the link, so what is missing now is not the place (the
    station went down, the link is jammed), and every metre more is a metre further from where the operator left the
    robot, unless the owner expects the station's range to shrink and says how far to look (docs/architecture.md
    §6)."""
    total = polyline_length(pts)
    nowhere = min(total, at + seek)
    if gap is None:
        return nowhere
    again = linkmap.first_reliable(pts, skip=_along(pts, *gap))
    if again is None:
        return nowhere
    return min(total, max(nowhere, _along(pts, *again) + depth))


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
