"""The breadcrumb trail: where the robot has been, by its own estimate, and whether it could hear the operator there.

Why it looks like this (docs/architecture.md §6, and what SmartRTL gets wrong):

* Crumbs come from the estimator, never from ground truth, so the same code runs on a real robot.
* Simplification is online and O(1) per crumb: a *sleeve* (angular wedge) from the last kept point narrows with
  every new crumb; a crumb is only kept when the wedge can no longer contain the path within the tolerance. Every
  dropped crumb therefore lies within the tolerance of the kept polyline - a guarantee, not a heuristic.
* Link transitions are anchors: the last crumb with a good link before a loss is always kept, so the return target
  chosen from the compressed trail is the one the full trail would give.
* Loops are found with a spatial hash of the kept segments (cells of TRL_LOOP_D), so each crumb costs a look at
  nine cells instead of SmartRTL's O(n^2) pair scan. A kept point remembers the earliest older segment within
  TRL_LOOP_D (its *shortcut*); the route planner follows shortcuts to skip loops.
* A fold-back (the robot backs up, or U-turns tighter than TRL_LOOP_D, over its own track) is a loop of zero width:
  it never crosses the stretch it runs back along, and that stretch is the one just behind, so the path-length rule
  alone would never see it. A crumb heading back along a kept segment gets that segment as its shortcut, so a later
  return from the folded part does not first drive out to the turn point. Nothing is dropped for it: the folded
  crumbs keep their own link tags and anchors, and the return target is chosen from them as before.
* Memory is preallocated and bounded by TRL_MAX_PTS. When it is full the oldest half is re-simplified with twice
  the tolerance (its part's tolerance is recorded), so the trail degrades gracefully and never deactivates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from link.parameters import default

if TYPE_CHECKING:
    from vehicle.params import Params

FOLD_SLOPE = 0.5  # a fold-back heads back within atan(0.5) (about 27 degrees) of the stretch it runs along


@dataclass(frozen=True)
class TrailConfig:
    """The TRL_* parameters; defaults from the parameter table."""

    spacing: float = default("TRL_SPACING")
    tolerance: float = default("TRL_TOL")
    loop_distance: float = default("TRL_LOOP_D")
    max_points: int = int(default("TRL_MAX_PTS"))

    @classmethod
    def from_params(cls, params: Params) -> TrailConfig:
        return cls(spacing=params["TRL_SPACING"], tolerance=params["TRL_TOL"],
                   loop_distance=params["TRL_LOOP_D"], max_points=int(params["TRL_MAX_PTS"]))


class Crumb(NamedTuple):
    """One estimator output as the trail sees it: an immutable record, laid every tick."""

    x: float
    y: float
    t: float
    std: float = 0.0
    link_good: bool = True
    rssi: float = math.nan
    speed: float = math.nan  # the ground speed driven when it was laid (m/s), smoothed over a few ticks


def seg_dist(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    """Distance from (px, py) to the segment a-b (also the SmartRTL baseline's loop test, sim/policies/smartrtl.py)."""
    dx, dy = bx - ax, by - ay
    L2 = dx * dx + dy * dy
    if L2 <= 1e-18:
        return math.hypot(px - ax, py - ay)
    u = max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / L2))
    return math.hypot(px - ax - u * dx, py - ay - u * dy)


def _fmax(a: float, b: float) -> float:
    """max ignoring nan (an unknown speed): the cheap scalar form of ``np.fmax`` for the per-tick path."""
    if a != a:
        return b
    return a if b != b or a >= b else b


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class Trail:
    """Kept crumbs in preallocated arrays, oldest first. Mutable: it is the one stateful part of the planner's
    input, updated once per estimator output; everything that reads it (targets, routes) is a pure function."""

    FIELDS = ("x", "y", "t", "std", "rssi", "tol", "pace")

    def __init__(self, config: TrailConfig | None = None) -> None:
        self.config = config or TrailConfig()
        n = self.config.max_points
        self._f = np.zeros((n, len(self.FIELDS)), dtype=np.float64)
        self._good = np.zeros(n, dtype=bool)
        self._anchor = np.zeros(n, dtype=bool)
        self._shortcut = np.full(n, -1, dtype=np.int64)
        self.count = 0
        self.compactions = 0
        self.crumbs_seen = 0
        self._grid: dict[tuple[int, int], list[int]] = {}
        self._run_loop = -1  # loop found by the previous crumb (-1: none): a new run of overlap starts a point
        self._reset_pending()
        self._pace = math.nan  # fastest crumb speed since the last kept point: the pace of the stretch into the next
        self._last: Crumb | None = None  # last crumb seen (recorded or not)
        self._rec: Crumb | None = None  # last crumb recorded (spacing reference)

    # ----- reading -----------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.count + (1 if self._pend is not None else 0)

    def point(self, i: int) -> tuple[float, float]:
        if i == self.count and self._pend is not None:
            return self._pend.x, self._pend.y
        return float(self._f[i, 0]), float(self._f[i, 1])

    def points(self) -> np.ndarray:
        """Kept points plus the newest crumb (the open end of the sleeve), shape (n, 2)."""
        pts = self._f[: self.count, :2].copy()
        if self._pend is not None:
            pts = np.vstack([pts, [[self._pend.x, self._pend.y]]])
        return pts

    def link_good(self) -> np.ndarray:
        good = self._good[: self.count].copy()
        if self._pend is not None:
            good = np.append(good, self._pend.link_good)
        return good

    def times(self) -> np.ndarray:
        t = self._f[: self.count, 2].copy()
        if self._pend is not None:
            t = np.append(t, self._pend.t)
        return t

    def paces(self) -> np.ndarray:
        """Per point: the fastest speed driven on the stretch from the point before to it (nan: not known), the
        pace a return copies there; the time between crumbs also holds the stops and turns on the spot."""
        pace = self._f[: self.count, 6].copy()
        if self._pend is not None:
            pace = np.append(pace, self._pace)
        return pace

    def anchors(self) -> np.ndarray:
        return self._anchor[: self.count].copy()

    def tolerances(self) -> np.ndarray:
        """Per kept point: the tolerance its part of the trail was simplified with."""
        return self._f[: self.count, 5].copy()

    def shortcut(self, i: int) -> int:
        return int(self._shortcut[i]) if i < self.count else self._pend_shortcut

    @property
    def max_tolerance(self) -> float:
        return float(self._f[: self.count, 5].max()) if self.count else self.config.tolerance

    # ----- writing -----------------------------------------------------------------------------------------
    def add(self, crumb: Crumb) -> None:
        """Feed one estimator output. Amortised O(1)."""
        self.crumbs_seen += 1
        last, self._last = self._last, crumb
        transition = last is not None and last.link_good != crumb.link_good
        rec = self._rec
        if not transition and rec is not None and math.hypot(crumb.x - rec.x, crumb.y - rec.y) < self.config.spacing:
            self._pace = _fmax(self._pace, crumb.speed)  # on the open stretch (or, by one crumb, the next one)
            return
        self._rec = crumb
        if self.count == 0 and self._pend is None:
            self._commit(crumb, anchor=True)
            return
        if transition:
            # both sides of a link transition are anchors: the last crumb with the old tag, then the new one
            if last is not None and self._pend is not None and (last.x, last.y) != (self._pend.x, self._pend.y):
                self._extend(last)
            if self._pend is not None:
                self._commit(self._pend, anchor=True)
                self._reset_pending()
            self._commit(crumb, anchor=True)
            return
        self._extend(crumb)

    # sleeve simplification -------------------------------------------------------------------------------
    def _reset_pending(self) -> None:
        self._pend: Crumb | None = None
        self._lo = -math.inf
        self._hi = math.inf
        self._base = 0.0  # direction the wedge is measured around
        self._maxd = 0.0
        self._pend_shortcut = -1

    def _extend(self, c: Crumb) -> None:
        # the sleeve first: when c breaks it (a turn, or the robot coming back), its open end becomes a kept point
        # before c is looked up, so a fold-back is seen against the stretch it runs back along
        if self._pend is not None and not self._fits(c):
            self._commit(self._pend, anchor=False)
            self._reset_pending()
        loop = self._find_loop(c.x, c.y)
        entering = loop >= 0 and self._run_loop < 0
        self._run_loop = loop
        if entering:
            # the trail comes back onto itself here: keep the crossing as a point of its own, with its shortcut
            if self._pend is not None:
                self._commit(self._pend, anchor=False)
                self._reset_pending()
            self._commit(c, anchor=False, shortcut=loop)
            return
        tol = self.config.tolerance
        ax, ay = self._f[self.count - 1, 0], self._f[self.count - 1, 1]
        dx, dy = c.x - ax, c.y - ay
        d = math.hypot(dx, dy)
        if self._pend is None:
            self._base = math.atan2(dy, dx) if d > 0 else 0.0
        # narrow the wedge by this crumb's own cone
        if d > tol:
            ang = _wrap(math.atan2(dy, dx) - self._base)
            half = math.asin(min(1.0, tol / d))
            self._lo = max(self._lo, ang - half)
            self._hi = min(self._hi, ang + half)
        self._maxd = max(self._maxd, d)
        self._pace = _fmax(self._pace, c.speed)
        self._pend = c
        self._pend_shortcut = loop  # the open end's own shortcut: the newest crumb's is the one a return uses

    def _fits(self, c: Crumb) -> bool:
        """Whether the open sleeve from the last kept point still holds c (and so every crumb since, within TRL_TOL)."""
        tol = self.config.tolerance
        dx, dy = c.x - self._f[self.count - 1, 0], c.y - self._f[self.count - 1, 1]
        d = math.hypot(dx, dy)
        if d <= tol:
            return d >= self._maxd - tol
        ang = _wrap(math.atan2(dy, dx) - self._base)
        return self._lo <= ang <= self._hi and d >= self._maxd - tol

    def _commit(self, c: Crumb, anchor: bool, shortcut: int | None = None) -> None:
        if shortcut is None:
            shortcut = self._pend_shortcut if c is self._pend else -1
        if self.count >= self.config.max_points:
            shortcut = self._compact(shortcut)
        i = self.count
        pace = self._pace if c is self._pend else _fmax(self._pace, c.speed)  # the open end's is already in
        self._f[i] = (c.x, c.y, c.t, c.std, c.rssi, self.config.tolerance, pace)
        self._pace = math.nan
        self._good[i] = c.link_good
        self._anchor[i] = anchor
        self._shortcut[i] = shortcut
        self.count += 1
        if i > 0:
            self._grid_add(i - 1)

    # loop index ------------------------------------------------------------------------------------------
    def _cell(self, x: float, y: float) -> tuple[int, int]:
        s = self.config.loop_distance
        return int(math.floor(x / s)), int(math.floor(y / s))

    def _grid_add(self, seg: int) -> None:
        """Register kept segment seg -> seg+1 in every cell it passes (cost ~ its length / cell size)."""
        ax, ay, bx, by = self._f[seg, 0], self._f[seg, 1], self._f[seg + 1, 0], self._f[seg + 1, 1]
        steps = max(1, int(math.hypot(bx - ax, by - ay) / (0.5 * self.config.loop_distance)) + 1)
        seen = set()
        for k in range(steps + 1):
            u = k / steps
            cell = self._cell(ax + u * (bx - ax), ay + u * (by - ay))
            if cell not in seen:
                seen.add(cell)
                self._grid.setdefault(cell, []).append(seg)

    def _find_loop(self, x: float, y: float) -> int:
        """The earliest kept segment within TRL_LOOP_D of (x, y) that is not just the trail behind us (or is, but
        (x, y) is coming back along it)."""
        if self.count < 2:
            return -1
        L = self.config.loop_distance
        cx, cy = self._cell(x, y)
        best = -1
        for gx in (cx - 1, cx, cx + 1):
            for gy in (cy - 1, cy, cy + 1):
                for seg in self._grid.get((gx, gy), ()):
                    if best != -1 and seg >= best:
                        break
                    f = self._f
                    if seg_dist(x, y, f[seg, 0], f[seg, 1], f[seg + 1, 0], f[seg + 1, 1]) >= L:
                        continue
                    # the trail just behind us is always near: only a return after 3 L of path closes a loop, or a
                    # fold-back (a loop of zero width, which no amount of path makes cross itself)
                    if not self._folds_back(x, y, seg) and self._path_length_since(seg + 1, x, y) < 3.0 * L:
                        continue
                    best = seg
                    break
        return best

    def _folds_back(self, x: float, y: float, seg: int) -> bool:
        """Whether (x, y) lies back along kept segment seg: behind its end by more than the tolerance (so not the
        noise around a turn point) and within a narrow cone around it (heading back, not rounding a corner).

        This is how a robot that backs up, or U-turns tighter than TRL_LOOP_D, comes back over its own track: the
        new stretch runs along the previous one and never crosses it, and that previous stretch is the one just
        behind, which the path-length rule must exclude."""
        f = self._f
        tol = max(self.config.tolerance, f[seg + 1, 5])
        ax, ay, bx, by = f[seg, 0], f[seg, 1], f[seg + 1, 0], f[seg + 1, 1]
        length = math.hypot(bx - ax, by - ay)
        if length <= tol:
            return False  # no direction to run back along (the two sides of a link transition, say)
        ux, uy = (bx - ax) / length, (by - ay) / length
        rx, ry = x - bx, y - by
        back = -(rx * ux + ry * uy)
        across = abs(rx * uy - ry * ux)
        return back > tol and across <= FOLD_SLOPE * back

    def _path_length_since(self, i: int, x: float, y: float) -> float:
        """Path length from kept point i to (x, y), bounded early: we only need to know if it exceeds 3 L."""
        limit = 3.0 * self.config.loop_distance
        total = 0.0
        f = self._f
        for k in range(i, self.count - 1):
            total += math.hypot(f[k + 1, 0] - f[k, 0], f[k + 1, 1] - f[k, 1])
            if total >= limit:
                return total
        return total + math.hypot(x - f[self.count - 1, 0], y - f[self.count - 1, 1])

    # bounded memory --------------------------------------------------------------------------------------
    def _compact(self, pending_shortcut: int) -> int:
        """Re-simplify the oldest half with a doubled tolerance until an eighth of the memory is free.

        Each compaction costs O(n) and frees n/8 slots, so at least n/8 crumbs are kept between two of them:
        amortised O(1) per crumb."""
        self.compactions += 1
        n = self.count
        half = n // 2
        keep = np.ones(n, dtype=bool)
        tol = self._f[:half, 5].max() if half else self.config.tolerance
        target_free = max(1, self.config.max_points // 8)
        for _ in range(12):
            tol *= 2.0
            keep[:half] = douglas_peucker(self._f[:half + 1, :2], tol, self._anchor[:half + 1])[:half]
            if n - int(keep.sum()) >= target_free:
                break
        else:
            # anchors alone fill the old half: drop every other old anchor (the oldest information goes first)
            idx = np.flatnonzero(keep[:half])
            keep[idx[1::2]] = False
        self._f[:half, 5] = np.where(keep[:half], np.maximum(self._f[:half, 5], tol), self._f[:half, 5])
        # a kept point's stretch now runs from the kept point before it: its pace is the fastest of those merged
        kept_idx = np.flatnonzero(keep)
        self._f[kept_idx, 6] = np.fmax.reduceat(self._f[:n, 6], np.concatenate([[0], kept_idx[:-1] + 1]))
        old_to_new = np.cumsum(keep) - 1
        for arr in (self._f, self._good, self._anchor, self._shortcut):
            kept = arr[:n][keep].copy()
            arr[: len(kept)] = kept
        self.count = int(keep.sum())
        sc = self._shortcut[: self.count]
        valid = sc >= 0
        sc[valid] = old_to_new[sc[valid]]
        if self._pend_shortcut >= 0:
            self._pend_shortcut = int(old_to_new[self._pend_shortcut])
        if self._run_loop >= 0:
            self._run_loop = int(old_to_new[self._run_loop])
        self._grid = {}
        for seg in range(self.count - 1):
            self._grid_add(seg)
        return int(old_to_new[pending_shortcut]) if pending_shortcut >= 0 else -1


def douglas_peucker(pts: np.ndarray, tol: float, anchors: np.ndarray) -> np.ndarray:
    """Keep-mask of an iterative Douglas-Peucker that never drops anchors (or the two ends)."""
    n = len(pts)
    keep = np.zeros(n, dtype=bool)
    keep[0] = keep[-1] = True
    keep |= anchors[:n]
    marks = np.flatnonzero(keep)
    stack = list(zip(marks[:-1], marks[1:], strict=True))
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg = pts[b] - pts[a]
        rel = pts[a + 1 : b] - pts[a]
        L2 = float(seg @ seg)
        if L2 < 1e-18:
            d = np.hypot(rel[:, 0], rel[:, 1])
        else:
            u = np.clip(rel @ seg / L2, 0.0, 1.0)
            d = np.hypot(rel[:, 0] - u * seg[0], rel[:, 1] - u * seg[1])
        k = int(np.argmax(d))
        if d[k] > tol:
            m = a + 1 + k
            keep[m] = True
            stack.append((a, m))
            stack.append((m, b))
    return keep
