"""A baseline that follows ArduPilot SmartRTL's documented rules, for comparison only.

Documented behaviour (SmartRTL, ArduPilot wiki and parameter docs): the position is sampled at 3 Hz and a point is
added when the vehicle has moved more than SMARTRTL_ACCURACY (2 m) from the last point; the path is simplified with
a tolerance of 1 m and loops are cut where two segments come closer than 0.99 x accuracy (1.98 m), using a pairwise
segment scan; the buffer holds SMARTRTL_POINTS (300) points, and when it stays full for 15 s SmartRTL deactivates.
"""

from __future__ import annotations

import math

import numpy as np


def _seg_seg_dist(p1, p2, q1, q2) -> float:
    def pt_seg(p, a, b):
        ab = b - a
        L2 = float(ab @ ab)
        u = 0.0 if L2 == 0 else min(1.0, max(0.0, float((p - a) @ ab) / L2))
        return float(np.hypot(*(p - a - u * ab)))

    return min(pt_seg(p1, q1, q2), pt_seg(p2, q1, q2), pt_seg(q1, p1, p2), pt_seg(q2, p1, p2))


def _rdp(pts: list[np.ndarray], tol: float) -> list[np.ndarray]:
    if len(pts) < 3:
        return pts
    keep = [False] * len(pts)
    keep[0] = keep[-1] = True
    stack = [(0, len(pts) - 1)]
    while stack:
        a, b = stack.pop()
        best, idx = 0.0, -1
        ab = pts[b] - pts[a]
        L2 = float(ab @ ab)
        for k in range(a + 1, b):
            ap = pts[k] - pts[a]
            u = 0.0 if L2 == 0 else min(1.0, max(0.0, float(ap @ ab) / L2))
            d = float(np.hypot(*(ap - u * ab)))
            if d > best:
                best, idx = d, k
        if best > tol:
            keep[idx] = True
            stack += [(a, idx), (idx, b)]
    return [p for p, k in zip(pts, keep, strict=True) if k]


class SmartRTLBaseline:
    def __init__(self, accuracy: float = 2.0, max_points: int = 300, timeout: float = 15.0) -> None:
        self.accuracy, self.max_points, self.timeout = accuracy, max_points, timeout
        self.points: list[np.ndarray] = []
        self.active = True
        self.deactivated_at: float | None = None
        self._next_sample = 0.0
        self._full_since: float | None = None
        self.pair_checks = 0

    def update(self, x: float, y: float, t: float) -> None:
        if not self.active or t < self._next_sample:
            return
        self._next_sample = t + 1.0 / 3.0
        p = np.array([x, y])
        if self.points and math.hypot(*(p - self.points[-1])) <= self.accuracy:
            return
        if len(self.points) >= self.max_points:
            self._cleanup()
        if len(self.points) >= self.max_points:
            if self._full_since is None:
                self._full_since = t
            if t - self._full_since >= self.timeout:
                self.active = False
                self.deactivated_at = t
            return
        self._full_since = None
        self.points.append(p)

    def _cleanup(self) -> None:
        self.points = _rdp(self.points, 1.0)
        # loop pruning: O(n^2) pair scan of non-adjacent segments
        pts = self.points
        i = 0
        while i < len(pts) - 3:
            cut = None
            for j in range(len(pts) - 2, i + 1, -1):
                self.pair_checks += 1
                if _seg_seg_dist(pts[i], pts[i + 1], pts[j], pts[j + 1]) < 0.99 * self.accuracy:
                    cut = j
                    break
            if cut is not None:
                pts = pts[: i + 1] + pts[cut + 1 :]
            i += 1
        self.points = pts
