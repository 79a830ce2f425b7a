"""Speed of a PX4 run: the 10-minute `tunnel` flown by the real PX4 rover SITL through the HIL bridge (vehicle
``px4rover``, policy px4-return), as wall-clock real-time factor (docs/architecture.md §10.1: >= 10x), next to the
bridge's own CPU (this process: physics at 250 Hz, HIL messages, radio, operator, MAVLink parsing).

Wall time is the figure by nature (two processes in lockstep on PX4's sensor clock), so a busy machine lowers it.
PX4 comes from --px4 DIR or RETURNLINK_PX4; without one the benchmark says so and exits 0.

    python benchmarks/px4_bench.py [--repeat 3] [--minutes 10] [--px4 DIR]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from sim.px4.locate import PX4NotFound, find_px4
from sim.runner import Run
from sim.scenario import load

TARGET_X = 10.0  # docs/architecture.md §10.1: a 10-minute tunnel run with PX4 at >= 10x real time, wall clock


def once(px4: Path, minutes: float) -> dict:
    sc = load("tunnel")
    run = Run(sc, "px4rover", 1, policy="px4-return", px4=px4)
    run.duration = 60 * minutes
    c0, w0 = time.process_time(), time.perf_counter()
    run.run()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return {"x": run.duration / wall, "wall": wall, "bridge_cpu": cpu, "boot_s": run.plant.link.boot_s}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--px4")
    args = ap.parse_args()
    if args.repeat < 1 or not 0 < args.minutes <= 60:
        ap.error("--repeat must be at least 1 and --minutes in (0, 60]")
    try:
        px4 = find_px4(args.px4)
    except PX4NotFound as e:
        print(f"px4 bench: skipped, {e}")
        return 0
    print(f"px4 bench: tunnel, {args.minutes:g} simulated min, vehicle px4rover, policy px4-return, {args.repeat} runs")
    runs = []
    for k in range(args.repeat):
        r = once(px4, args.minutes)
        runs.append(r)
        print(f"  run {k + 1}: {r['x']:.1f}x real time (wall {r['wall']:.1f} s for {60 * args.minutes:g} s after "
              f"PX4 was ready {r['boot_s']:.1f} s into its clock), bridge CPU {r['bridge_cpu']:.1f} s", flush=True)
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    print(f"  median: {med['x']:.1f}x real time (target >= {TARGET_X:g}x, ratio {med['x'] / TARGET_X:.2f}); the "
          f"bridge's CPU is {100 * med['bridge_cpu'] / med['wall']:.0f} % of the wall time, the rest PX4's and waits")
    return 0


if __name__ == "__main__":
    sys.exit(main())
