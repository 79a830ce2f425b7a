"""Campaign throughput: trials of 200 simulated seconds per hour per core, in CPU time.

A fixed small campaign (tunnel and warehouse, rover and legged, 3 seeds, returnlink: 12 trials of 200 s) runs
twice: in this process (the trial's own CPU cost, what a core can do at best) and through a local Ray with every
core (what a sweep gets, start-up, worker imports and result transport included, counted as wall time x workers,
so it is the lower figure, and meaningless on a machine busy with other work: the load average is printed).

Aim (docs/architecture.md §8): at least 1,500 trials of 200 simulated s per hour per core.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

from sim.campaign.executors import RayExecutor, SerialExecutor
from sim.campaign.spec import parse_spec

AIM = 1500.0
SPEC = """
scenarios = ["tunnel", "warehouse"]
vehicles = ["rover", "legged"]
seeds = {from = 1, to = 3}
policies = ["returnlink"]
timeout_s = 600
"""


def per_hour_core(rows: list[dict], cpu_s: float) -> float:
    """Trials per hour per core, each trial counted in units of 200 simulated seconds."""
    sim_s = sum(r.get("sim_duration_s") or 0.0 for r in rows)
    return 3600.0 * (sim_s / 200.0) / cpu_s


def main() -> None:
    spec = parse_spec(SPEC, "campaign_bench", Path("."))
    trials = spec.trials
    print(f"{len(trials)} trials (tunnel, warehouse x rover, legged x 3 seeds, returnlink), 200 simulated s each")
    c0 = time.process_time()
    with SerialExecutor() as ex:
        rows = list(ex.map(trials, spec.timeout_s))
    serial_cpu = time.process_time() - c0
    errors = [r for r in rows if r["status"] == "error"]
    trial_cpu = sum(r["cpu_s"] for r in rows)
    print(f"{'where':<22} {'trials':>6} {'errors':>6} {'CPU s':>8} {'per hour per core':>18} {'vs aim':>7}")
    rate = per_hour_core(rows, trial_cpu)
    print(f"{'one process (trials)':<22} {len(rows):6d} {len(errors):6d} {trial_cpu:8.1f} {rate:18,.0f} "
          f"{rate / AIM:6.2f}x")
    rate = per_hour_core(rows, serial_cpu)
    print(f"{'one process (all)':<22} {len(rows):6d} {len(errors):6d} {serial_cpu:8.1f} {rate:18,.0f} "
          f"{rate / AIM:6.2f}x")
    cores = os.cpu_count() or 1
    with tempfile.TemporaryDirectory():
        w0 = time.perf_counter()
        with RayExecutor(workers=cores) as ex:
            started = time.perf_counter()
            ray_rows = list(ex.map(trials, spec.timeout_s))
            ran = time.perf_counter() - started
        wall = time.perf_counter() - w0
    ray_errors = sum(r["status"] == "error" for r in ray_rows)
    worker_cpu = sum(r["cpu_s"] or 0.0 for r in ray_rows)
    rate = per_hour_core(ray_rows, worker_cpu)
    print(f"{'Ray workers (trials)':<22} {len(ray_rows):6d} {ray_errors:6d} {worker_cpu:8.1f} {rate:18,.0f} "
          f"{rate / AIM:6.2f}x")
    for label, seconds in ((f"Ray wall x{cores} cores", ran), ("  with Ray's start", wall)):
        rate = per_hour_core(ray_rows, seconds * cores)
        print(f"{label:<22} {len(ray_rows):6d} {ray_errors:6d} {seconds * cores:8.1f} {rate:18,.0f} "
              f"{rate / AIM:6.2f}x")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"(wall-time rows count every core as ours; the 1-minute load average was {load:.1f} on {cores} cores)")
    if errors or ray_errors:
        print("errors: " + "; ".join(sorted({r['error'] for r in errors + ray_rows if r['status'] == 'error'})),
              file=sys.stderr)
        raise SystemExit(1)


if __name__ == "__main__":
    main()
