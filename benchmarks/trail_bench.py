"""Trail memory, accuracy and cost on a 10 km random route with loops, next to a SmartRTL-rules baseline.

Aim (issue): at 0.25 m tolerance, 10 km in at most 2000 points, under 20 us per update.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from sim.policies.smartrtl import SmartRTLPath
from vehicle.trail import Crumb, Trail, TrailConfig


def route(length_m: float = 10_000.0, speed: float = 1.5, hz: float = 50.0, seed: int = 7,
          loops: bool = True) -> np.ndarray:
    """Smooth random driving with the odd full circle (a loop over its own track), or, without loops, a winding
    trek whose heading wanders around one bearing (it never comes back on itself)."""
    rng = np.random.default_rng(seed)
    n = int(length_m / speed * hz)
    dt = 1.0 / hz
    yaw_rate = np.zeros(n)
    k = 0
    while k < n:
        run = int(rng.uniform(2, 15) * hz)
        if loops and rng.random() < 0.08:
            # a loop: a full circle of radius 4-10 m
            r = rng.uniform(4, 10)
            run = int(2 * math.pi * r / speed * hz)
            yaw_rate[k : k + run] = speed / r * rng.choice([-1, 1])
        else:
            yaw_rate[k : k + run] = rng.normal(0, 0.3)
        k += run
    yaw = np.cumsum(yaw_rate[:n] * dt)
    if not loops:
        yaw = 1.2 * np.sin(yaw)  # wander within +-70 degrees of north
    xy = np.cumsum(np.stack([np.cos(yaw), np.sin(yaw)], axis=1) * speed * dt, axis=0)
    return xy


def max_deviation(points: np.ndarray, poly: np.ndarray, stride: int = 5) -> float:
    """Largest distance from the driven path (every ``stride``-th sample) to the kept polyline."""
    p = points[::stride]
    best = np.full(len(p), np.inf)
    for a, b in zip(poly[:-1], poly[1:], strict=True):
        ab = b - a
        L2 = float(ab @ ab)
        ap = p - a
        u = np.clip(ap @ ab / L2, 0, 1) if L2 > 0 else np.zeros(len(p))
        d = np.hypot(ap[:, 0] - u * ab[0], ap[:, 1] - u * ab[1])
        np.minimum(best, d, out=best)
    return float(best.max())


def compare(name: str, xy: np.ndarray) -> None:
    n = len(xy)
    dt = 1.0 / 50.0
    cfg = TrailConfig(spacing=0.5, tolerance=0.25, loop_distance=1.0, max_points=2000)
    trail = Trail(cfg)
    base = SmartRTLPath()
    ours_at_off = None
    crumbs = [Crumb(float(x), float(y), k * dt) for k, (x, y) in enumerate(xy)]
    t0 = time.perf_counter()
    for c in crumbs:
        trail.add(c)
    ours_us = (time.perf_counter() - t0) / n * 1e6
    t0 = time.perf_counter()
    for k, (x, y) in enumerate(xy):
        was = base.active
        base.update(float(x), float(y), k * dt)
        if was and not base.active:
            ours_at_off = k
    base_us = (time.perf_counter() - t0) / n * 1e6
    km = float(np.hypot(*np.diff(xy, axis=0).T).sum()) / 1000
    pts = trail.points()
    dev = max_deviation(xy, pts)
    print(f"\n{name} route: {km:.1f} km, {n:,} estimator updates at 50 Hz")
    print(f"{'':28}{'returnlink trail':>20}{'SmartRTL rules':>18}")
    print(f"{'points kept':28}{len(pts):>20,}{len(base.points):>18,}")
    print(f"{'us per update':28}{ours_us:>20.2f}{base_us:>18.2f}")
    print(f"{'compactions / pair checks':28}{trail.compactions:>20,}{base.pair_checks:>18,}")
    print(f"{'tolerance (newest..oldest)':28}{cfg.tolerance:>11.2f}..{trail.max_tolerance:<7.2f}{1.0:>18.2f}")
    print(f"{'max deviation from path m':28}{dev:>20.2f}{'(loops cut)':>18}")
    if base.deactivated_at is not None:
        k = ours_at_off or 0
        t = Trail(cfg)
        for c in crumbs[: k + 1]:
            t.add(c)
        driven = float(np.hypot(*np.diff(xy[: k + 1], axis=0).T).sum())
        print(f"SmartRTL switched itself off at t={base.deactivated_at:.0f} s after {driven / 1000:.2f} km; "
              f"our trail then held {len(t):,} points covering all of it, and at the end {len(pts):,} for "
              f"{km:.1f} km")
    else:
        print("SmartRTL stayed active")
    print(f"ratio: {ours_us / 20.0:.2f} of the 20 us budget; {len(pts) / 2000:.2f} of the 2000-point budget")


def main() -> None:
    compare("looping", route(loops=True))
    compare("winding trek", route(loops=False, seed=8))
    print(f"\nplot: {plot_loop_return(Path('out/bench/trail_route.png'))}")


def plot_loop_return(out: Path) -> Path:
    """The loop scenario driven for real: its trail (tagged by line of sight to the antenna) and the return route."""
    from sim import scenario
    from sim.drive import Rig
    from sim.plots import trail_route_figure
    from vehicle.returning import Target, plan_route

    s = scenario.load("loop")
    rig = Rig(s)
    gcs = s.stations[0]

    def los(x: float, y: float) -> bool:
        return rig.world.attenuation_db((gcs.x, gcs.y), (x, y)) < 20.0

    rig.drive_route(link_good=los)
    p = rig.estimator.pose
    r = plan_route(rig.trail, (p.x, p.y), Target.LINK, 50.0, link_lost=True)
    return trail_route_figure(rig.world, s.bounds, np.array(rig.log.true), np.array(rig.log.est),
                              rig.trail.points(), rig.trail.link_good(), r.points, 50.0,
                              f"loop: return route {r.length:.1f} m over a {len(rig.trail)}-point trail", out)


if __name__ == "__main__":
    main()
