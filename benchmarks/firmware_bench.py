"""Speed of a firmware run: the 10-minute `tunnel` flown by the real ArduPilot Rover SITL through the JSON bridge,
as wall-clock real-time factor (docs/architecture.md §10: >= 30x, the bridge on one core), next to where the time
goes: the bridge's own CPU (this process: physics, JSON answers, radio, operator, MAVLink parsing), the
firmware's CPU (its process, from /proc), and the rest (waiting on each other over loopback).

Wall time is the figure here by nature (two processes in lockstep; the firmware's share is not this process's
CPU), so a busy machine lowers it: the CPU split says how much of a run was each side's work. The firmware comes
from RETURNLINK_ARDUROVER, --firmware or PATH; without one the benchmark says so and exits 0.

    python benchmarks/firmware_bench.py [--repeat 3] [--minutes 10] [--firmware PATH]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

from sim.firmware.locate import FirmwareNotFound, find_firmware
from sim.firmware_runs import FirmwareRun
from sim.scenario import load

TARGET_X = 30.0  # docs/architecture.md §10: a 10-minute tunnel run with the firmware at >= 30x real time, wall clock


def _child_cpu(pid: int) -> float:
    """User+system CPU seconds of process ``pid`` so far (Linux /proc), 0 if it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Measured(FirmwareRun):
    """The run, noting the firmware's CPU at the end of the loop, before its process is stopped."""

    firmware_cpu = 0.0

    def _loop(self) -> None:
        super()._loop()
        self.firmware_cpu = _child_cpu(self.link.process.pid)


def once(firmware: Path, minutes: float) -> dict:
    sc = load("tunnel")
    c0, w0 = time.process_time(), time.perf_counter()
    run = Measured(sc, 1, "ardupilot-smartrtl", firmware, duration=60 * minutes).run()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    sim_s = run.t + run.link.boot_s
    return {"x": run.t / wall, "x_all": sim_s / wall, "wall": wall, "bridge_cpu": cpu,
            "firmware_cpu": run.firmware_cpu, "boot_s": run.link.boot_s, "frames": sum(run.link.rules.counts.values())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--firmware")
    args = ap.parse_args()
    try:
        firmware = find_firmware(args.firmware)
    except FirmwareNotFound as e:
        print(f"firmware bench: skipped, {e}")
        return 0
    print(f"firmware bench: tunnel, {args.minutes:g} simulated min, policy ardupilot-smartrtl, {args.repeat} runs")
    runs = []
    for k in range(args.repeat):
        r = once(firmware, args.minutes)
        runs.append(r)
        print(f"  run {k + 1}: {r['x']:.1f}x real time (wall {r['wall']:.1f} s for {60 * args.minutes:g} s + "
              f"{r['boot_s']:.1f} s boot; {r['frames']} frames), bridge CPU {r['bridge_cpu']:.1f} s, "
              f"firmware CPU {r['firmware_cpu']:.1f} s", flush=True)
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    per_frame = 1e6 * med["wall"] / med["frames"]
    print(f"  median: {med['x']:.1f}x real time (target >= {TARGET_X:g}x, ratio {med['x'] / TARGET_X:.2f}); "
          f"{per_frame:.0f} us of wall per 5 ms frame")
    print(f"  where a frame's wall time goes (medians): bridge CPU {1e6 * med['bridge_cpu'] / med['frames']:.0f} us, "
          f"firmware CPU {1e6 * med['firmware_cpu'] / med['frames']:.0f} us; the two overlap (the bridge steps "
          "the physics while the firmware computes), and the rest is loopback and scheduling")
    return 0


if __name__ == "__main__":
    sys.exit(main())
