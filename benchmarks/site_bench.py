"""Your own site's speed and size (docs/architecture.md §7.2): a 100 m x 100 m map at 0.05 m (4 M cells) loaded and
ready to fly (read, plan, route: at most 10 s of wall time), a run on it in CPU time against the built-in `tunnel`
run in the same process (at least 150x real time), and the process's peak memory (under 1 GB).

The map is drawn here, as a robot's SLAM would leave a building: rooms off a grid of corridors, walls a few cells
thick with doors, the unmapped inside of walls and the outside unknown. Every figure is the median of ``--repeat``
runs; the run figures are CPU time of this process (``time.process_time``), the load figure wall time (what a user
waits for).

    python benchmarks/site_bench.py [--repeat 3] [--seed 1]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

FREE, OCCUPIED, UNKNOWN = 254, 0, 205
SIZE_M, RES = 100.0, 0.05
LOAD_TARGET_S = 10.0
RUN_TARGET_X = 150.0
MEMORY_TARGET_MB = 1024.0


def big_building(directory: Path) -> tuple[Path, tuple[float, float]]:
    """A 100 m x 100 m building at 0.05 m: 4 x 4 blocks of rooms between 4 m corridors; the station in the
    south-west corner's corridor. Returns the YAML and the station (map frame)."""
    n = round(SIZE_M / RES)
    cells = np.full((n, n), UNKNOWN, dtype=np.uint8)

    def box(x0, y0, x1, y1, v):  # metres, y up (image rows count down)
        cells[n - round(y1 / RES):n - round(y0 / RES), round(x0 / RES):round(x1 / RES)] = v

    box(2, 2, 98, 98, FREE)
    wall = 0.15
    for k in range(5):  # corridors 4 m wide along x and y every 24 m; rooms of 6 m between them
        c = 2 + k * 24
        if k < 4:
            for i in range(4):  # the block between corridors: 3 x 3 rooms of 6.67 m, walls and doors
                x0, y0 = c + 4, 2 + i * 24 + 4
                x1, y1 = x0 + 20, y0 + 20
                box(x0, y0, x1, y1, OCCUPIED)
                box(x0 + wall, y0 + wall, x1 - wall, y1 - wall, FREE)
                for r in range(1, 3):
                    box(x0 + r * 20 / 3, y0, x0 + r * 20 / 3 + wall, y1, OCCUPIED)
                    box(x0, y0 + r * 20 / 3, x1, y0 + r * 20 / 3 + wall, OCCUPIED)
                for r in range(3):
                    for q in range(3):
                        cx, cy = x0 + (r + 0.5) * 20 / 3, y0 + q * 20 / 3
                        box(cx - 1.2, cy, cx + 1.2, cy + wall, FREE)  # a 2.4 m door in each room's south wall
    box(0, 0, 100, 2, UNKNOWN)
    directory.mkdir(parents=True, exist_ok=True)
    h, w = cells.shape
    (directory / "big.pgm").write_bytes(f"P5\n{w} {h}\n255\n".encode() + cells.tobytes())
    (directory / "big.yaml").write_text(f"image: big.pgm\nresolution: {RES}\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
                                        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return directory / "big.yaml", (4.0, 4.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    from sim import outputs
    from sim.maps import mapfile
    from sim.runner import Run
    from sim.worlds import map_routes as routes
    from sim.worlds.resolve import load

    with tempfile.TemporaryDirectory() as tmp:
        yaml, station = big_building(Path(tmp))
        loads, runs, tunnel = [], [], []
        for k in range(a.repeat):
            mapfile._read.cache_clear()
            routes.plan.cache_clear()
            t = time.perf_counter()
            sc, redraws = load(f"map:{yaml}", a.seed + k, station=station)
            loads.append(time.perf_counter() - t)
            t = time.process_time()
            run = Run(sc, "rover", a.seed + k, progress=False).run()
            cpu = time.process_time() - t
            m = outputs.compute(run)
            runs.append(m["sim_duration_s"] / cpu)
            print(f"  map run {k + 1}: loaded in {loads[-1]:.2f} s, {m['sim_duration_s']:.0f} simulated s in "
                  f"{cpu:.2f} CPU s ({runs[-1]:.0f}x), passed {m['passed']}, walls in the physics "
                  f"{run.world.edge_count if hasattr(run, 'world') else '?'}")
            tsc, _ = load("tunnel")
            t = time.process_time()
            trun = Run(tsc, "rover", a.seed + k, progress=False).run()
            tcpu = time.process_time() - t
            tunnel.append(outputs.compute(trun)["sim_duration_s"] / tcpu)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    load_s, run_x, tunnel_x = statistics.median(loads), statistics.median(runs), statistics.median(tunnel)
    print(f"4 M-cell map ({SIZE_M:g} m x {SIZE_M:g} m at {RES} m): loaded and ready to fly in {load_s:.2f} s (target "
          f"<= {LOAD_TARGET_S:g} s); flies at {run_x:.0f}x real time in CPU time (target >= {RUN_TARGET_X:g}x); the "
          f"built-in tunnel in the same process {tunnel_x:.0f}x (map / tunnel {run_x / tunnel_x:.2f}); peak memory "
          f"{peak:.0f} MB (target < {MEMORY_TARGET_MB:g} MB)")


if __name__ == "__main__":
    main()
