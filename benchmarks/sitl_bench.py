"""Lockstep SITL speed: a 10-minute `tunnel` run for each robot, full MAVLink encode/decode both ways through the
radio model, next to the floor of the same run with physics and estimator alone (the same commands replayed).

Aim (DESIGN §8): at least 200x real time on one core.
"""

from __future__ import annotations

import time

import numpy as np

from sim.driver import SimDriver
from sim.runner import Run
from sim.scenario import load
from vehicle.app import DT
from vehicle.estimator import Estimator

MINUTES = 10.0


def floor(run: Run) -> float:
    """Wall seconds for the same ticks with only the robot, its sensors and the estimator."""
    sc = run.scenario
    driver = SimDriver(sc, run.kind, np.random.default_rng(run.seed))
    x, y, yaw = sc.start
    est = Estimator(x, y, yaw, 0.0, pos_std=0.3, yaw_std=0.02)
    t = 0.0
    w0 = time.perf_counter()
    for speed, yaw_rate in run.trace.cmd:
        t = round(t + DT, 9)
        r = driver.read(t, DT)
        est.predict(r.speed, r.yaw_rate, t)
        if r.heading is not None:
            est.heading(r.heading, r.heading_std)
        if r.fix is not None:
            est.fix(r.fix.x, r.fix.y, r.fix.std)
        driver.command(speed, yaw_rate)
        driver.advance(DT)
    return time.perf_counter() - w0


def main() -> None:
    print(f"tunnel, {MINUTES:g} simulated minutes, 50 Hz, one core")
    print(f"{'vehicle':<8} {'real-time x':>11} {'us/tick':>8} {'floor x':>8} {'floor us/tick':>13} "
          f"{'floor share':>11} {'frames':>7} {'vs 200x':>7}")
    for kind in ("rover", "legged"):
        run = Run(load("tunnel"), kind, duration=MINUTES * 60).run()
        ticks = len(run.trace.t)
        base = floor(run)
        rtf = run.t / run.wall
        print(f"{kind:<8} {rtf:11.0f} {1e6 * run.wall / ticks:8.1f} {run.t / base:8.0f} {1e6 * base / ticks:13.1f} "
              f"{base / run.wall:10.0%} {run.bus.delivered:7d} {rtf / 200:6.2f}x")


if __name__ == "__main__":
    main()
