"""Lockstep SITL speed: a 10-minute `tunnel` run for each robot, full MAVLink encode/decode both ways through the
radio model, next to the floor of the same run with physics, sensors and estimator alone (the same commands
replayed), then where the tick goes, and the command round trip of `sim serve` on UDP loopback.

Every tick figure is CPU time of this process (``time.process_time``), never wall time: the machine may be busy
with other work, and CPU time is what one core of a campaign pays. Each figure is the median of ``--repeat`` runs.
The round trip is wall time by nature (a ground station waits for it), measured against the same ``Server`` class
`returnlink sim serve` runs, in a thread of this process, on a perfect link.

    python benchmarks/sitl_bench.py [--repeat 5] [--kind rover|legged] [--no-profile] [--no-roundtrip]
"""

from __future__ import annotations

import argparse
import cProfile
import math
import pstats
import random
import socket
import statistics
import threading
import time

from link.radio import subsystem_rng
from sim.driver import SimDriver
from sim.runner import Run
from sim.scenario import load
from vehicle.core import DT
from vehicle.estimator import Estimator

MINUTES = 10.0
# docs/architecture.md §8 (Quality bars, Performance): the lockstep tunnel run at >= 300x real time on one core, in CPU
# time.
TARGET_X = 300.0
ROUND_TRIPS = 120
KINDS = ("rover", "legged")
# docs/architecture.md §8: the COMMAND_ACK leaves in the tick the command came in (20 ms at 50 Hz)
ROUND_TRIP_TARGET_MS = 20.0

# Where a profiled function's own time is booked: the first prefix of its file path that matches. Helpers that
# belong to no subsystem (numpy, builtins, dataclasses...) are booked to whoever called them (see ``_booked``).
GROUPS = [
    ("vehicle/endpoint.py", "vehicle endpoint"), ("vehicle/services/telemetry.py", "telemetry"),
    ("vehicle/services/heartbeat.py", "telemetry"), ("vehicle/services/", "vehicle endpoint"),
    ("vehicle/estimator.py", "estimator"), ("filterpy/", "estimator"),
    ("sim/world.py", "physics"), ("sim/robots.py", "physics"), ("pymunk/", "physics"),
    ("sim/sensors.py", "sensors"), ("sim/driver.py", "sensors"),
    ("pymavlink/", "pymavlink (pack, parse)"), ("link/dialect", "pymavlink (pack, parse)"),
    ("vehicle/app.py", "vehicle loop"), ("vehicle/control.py", "vehicle loop"),
    ("vehicle/contingency.py", "vehicle loop"), ("vehicle/teleop.py", "vehicle loop"),
    ("vehicle/modes.py", "telemetry"), ("vehicle/lease", "lease"), ("vehicle/link_watch.py", "link watch"),
    ("vehicle/trail.py", "trail, return, navigation"), ("vehicle/returning.py", "trail, return, navigation"),
    ("vehicle/service.py", "trail, return, navigation"), ("vehicle/navigation.py", "trail, return, navigation"),
    ("vehicle/", "vehicle (other)"), ("link/radio.py", "radio + bus"), ("link/transports.py", "radio + bus"),
    ("link/proxy.py", "radio + bus"), ("link/signing.py", "signing"), ("gcs/", "ground stations"),
    ("sim/operator.py", "runner + operator"), ("sim/runner.py", "runner + operator"), ("sim/policies", "policy"),
]
HELPERS = ("numpy/", "scipy/", "dataclasses.py", "~", "hashlib", "struct", "enum.py", "functools.py", "typing.py",
           "abc.py", "copy.py", "math", "_weakrefset.py", "heapq")


def _group(path: str) -> str | None:
    for prefix, name in GROUPS:
        if prefix in path:
            return name
    return None


def _helper(func: tuple) -> bool:
    path = func[0]
    return _group(path) is None and (path == "~" or any(h in path for h in HELPERS))


def _booked(stats: pstats.Stats, func: tuple, seen: frozenset = frozenset()) -> dict[str, float]:
    """Shares of ``func``'s own time per subsystem: its own group, or, for a helper, its callers' groups weighted by
    the time spent in it from each caller (recursively, so numpy called from numpy still lands in the estimator)."""
    g = _group(func[0])
    if g is not None:
        return {g: 1.0}
    callers = stats.stats[func][4]
    if not _helper(func) or not callers or func in seen:
        return {"other" if not _helper(func) else f"{func[0].split('/')[-1]}:{func[2]}": 1.0}
    total = sum(edge[3] for edge in callers.values()) or 1.0
    out: dict[str, float] = {}
    for caller, edge in callers.items():
        for name, share in _booked(stats, caller, seen | {func}).items():
            out[name] = out.get(name, 0.0) + share * edge[3] / total
    return out


def profile_table(kind: str) -> list[tuple[str, float]]:
    """Per-subsystem share of one profiled run's time (cProfile inflates small calls, so shares, not µs)."""
    run = Run(load("tunnel"), kind, duration=MINUTES * 60)
    prof = cProfile.Profile()
    prof.enable()
    run.run()
    prof.disable()
    stats = pstats.Stats(prof)
    groups: dict[str, float] = {}
    for func, (_cc, _nc, tt, _ct, _callers) in stats.stats.items():
        for name, share in _booked(stats, func).items():
            groups[name] = groups.get(name, 0.0) + tt * share
    total = sum(groups.values())
    return sorted(((n, v / total) for n, v in groups.items()), key=lambda x: -x[1])


def floor(run: Run) -> float:
    """CPU seconds for the same ticks with only the robot, its sensors and the estimator."""
    sc = run.scenario
    driver = SimDriver(sc, run.kind, subsystem_rng(run.seed, "robot"), subsystem_rng(run.seed, "sensors"))
    x, y, yaw = sc.start
    est = Estimator(x, y, yaw, 0.0, pos_std=0.3, yaw_std=0.02)
    t = 0.0
    c0 = time.process_time()
    for speed, yaw_rate in run.trace.cmd:
        t = round(t + DT, 9)
        r = driver.read(t, DT)
        est.predict(r.speed, r.yaw_rate, t, r.accel)  # as the vehicle tick calls it, slip check included
        if r.heading is not None:
            est.heading(r.heading, r.heading_std)
        if r.fix is not None:
            est.fix(r.fix.x, r.fix.y, r.fix.std)
        driver.command(speed, yaw_rate)
        driver.advance(DT)
    return time.process_time() - c0


def physics(run: Run) -> tuple[float, float]:
    """CPU seconds for the same ticks with the robot's physics alone (command, contact push, pymunk step, body
    read-back), and for pymunk's ``Space.step`` alone in those ticks: the library call no Python change can make
    cheaper. Each is timed on a run of its own so the clock reads do not land in the other figure."""
    sc = run.scenario
    driver = SimDriver(sc, run.kind, subsystem_rng(run.seed, "robot"), subsystem_rng(run.seed, "sensors"))
    c0 = time.process_time()
    for speed, yaw_rate in run.trace.cmd:
        driver.command(speed, yaw_rate)
        driver.advance(DT)
    whole = time.process_time() - c0
    driver = SimDriver(sc, run.kind, subsystem_rng(run.seed, "robot"), subsystem_rng(run.seed, "sensors"))
    robot, space = driver.robot, driver.world.space
    steps = []
    for speed, yaw_rate in run.trace.cmd:
        robot.command(speed, yaw_rate)
        robot.before_step(DT)
        c0 = time.process_time()
        space.step(DT)
        steps.append(time.process_time() - c0)
        robot.after_step(DT)
    empty = []  # what the pair of clock reads costs by itself, taken off each step
    for _ in range(len(steps)):
        c0 = time.process_time()
        empty.append(time.process_time() - c0)
    return whole, max(0.0, sum(steps) - sum(empty))


def machine_pace() -> float:
    """CPU milliseconds of a fixed pure-Python loop (float arithmetic and dict stores, the interpreter work a tick
    is made of), the best of three. This VM's pace drifts by a quarter over hours, with every figure above it:
    printed beside them, it tells a slow spell from a slower commit."""
    best = math.inf
    for _ in range(3):
        c0 = time.process_time()
        table: dict[int, float] = {}
        s = 0.0
        for i in range(1_000_000):
            s += (i % 7) * 0.5
            table[i & 1023] = s
        best = min(best, time.process_time() - c0)
    return 1e3 * best


def timed_run(kind: str) -> tuple[Run, float]:
    run = Run(load("tunnel"), kind, duration=MINUTES * 60)
    c0 = time.process_time()
    run.run()
    return run, time.process_time() - c0


def round_trips(n: int = ROUND_TRIPS) -> list[float]:
    """Wall seconds from sending a COMMAND_LONG to receiving its COMMAND_ACK, ``n`` times at random phases of the
    vehicle's tick, against `sim serve`'s Server on 127.0.0.1 (perfect link), in a thread of this process."""
    from sim.serve import Server
    from vehicle.services.base import mav

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(1.0)
    server = Server(load("open"), port=0, peers=(sock.getsockname(),), perfect_link=True)
    stop = threading.Event()
    thread = threading.Thread(target=server.serve, kwargs={"stop": stop.is_set, "out": None}, daemon=True)
    thread.start()
    gcs, parser = mav.MAVLink(None, 255, 190), mav.MAVLink(None, 0, 0)
    rng = random.Random(1)
    out: list[float] = []
    try:
        for k in range(n):
            time.sleep(rng.uniform(0.0, 2 * DT))
            # REQUEST_MESSAGE for AUTOPILOT_VERSION: a read, answered, changes nothing; a new confirmation each time
            # so the vehicle's repeat guard never answers from its cache
            cmd = gcs.command_long_encode(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, k % 256, 148, 0, 0, 0, 0, 0, 0)
            w0 = time.perf_counter()
            sock.sendto(cmd.pack(gcs), server.address)
            while True:
                try:
                    data = sock.recv(65536)
                except TimeoutError:
                    break
                if any(m.get_type() == "COMMAND_ACK" and m.command == mav.MAV_CMD_REQUEST_MESSAGE
                       for m in parser.parse_buffer(data) or []):
                    out.append(time.perf_counter() - w0)
                    break
    finally:
        stop.set()
        thread.join(5)
        server.close()
        sock.close()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs per robot; the median is shown")
    ap.add_argument("--kind", choices=KINDS, action="append",
                    help="robot to measure (repeatable); both when not given")
    ap.add_argument("--no-profile", action="store_true")
    ap.add_argument("--no-roundtrip", action="store_true")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")
    kinds = args.kind or list(KINDS)
    print(f"tunnel, {MINUTES:g} simulated minutes, 50 Hz, CPU time of one core, median of {args.repeat} runs; "
          f"aim {TARGET_X:g}x (docs/architecture.md §8)")
    print(f"{'vehicle':<8} {'us/tick':>8} {'x real':>7} {'floor us':>9} {'floor x':>8} {'full/floor':>10} "
          f"{'frames':>7} {'vs aim':>7} {'physics':>8} {'pymunk':>7}   runs (us/tick)")
    for kind in kinds:
        full, base, phys, lib, frames = [], [], [], [], 0
        for _ in range(args.repeat):
            run, cpu = timed_run(kind)
            ticks = len(run.trace.t)
            full.append(1e6 * cpu / ticks)
            base.append(1e6 * floor(run) / ticks)
            whole, step = physics(run)
            phys.append(1e6 * whole / ticks)
            lib.append(1e6 * step / ticks)
            frames = run.bus.delivered
        us, fl = statistics.median(full), statistics.median(base)
        x = 1e6 * DT / us
        print(f"{kind:<8} {us:8.1f} {x:7.0f} {fl:9.1f} {1e6 * DT / fl:8.0f} {us / fl:10.2f} {frames:7d} "
              f"{x / TARGET_X:6.2f}x {statistics.median(phys):8.1f} {statistics.median(lib):7.1f}   "
              f"{' '.join(f'{v:.1f}' for v in full)}")
    print("floor: physics, sensors and estimator alone; physics: the robot's physics step alone; pymunk: its "
          "Space.step alone (the library's own floor)")
    print(f"machine pace: {machine_pace():.0f} ms CPU for a fixed pure-Python loop (lower is faster; compare runs "
          "taken at different times by it)")
    if not args.no_profile:
        for kind in kinds:
            print(f"\nwhere the {kind}'s tick goes (cProfile own time, helpers booked to their callers):")
            for name, share in profile_table(kind):
                if share >= 0.003:
                    print(f"  {name:<34} {share:6.1%}")
    if not args.no_roundtrip:
        rt = sorted(round_trips())
        if rt:
            p50, p99 = 1e3 * rt[len(rt) // 2], 1e3 * rt[min(len(rt) - 1, int(0.99 * len(rt)))]
            print(f"\ncommand round trip, sim serve on UDP loopback, perfect link, {len(rt)} commands: "
                  f"p50 {p50:.1f} ms, p99 {p99:.1f} ms (aim p99 <= {ROUND_TRIP_TARGET_MS:g} ms)")
        else:
            print("\ncommand round trip: no COMMAND_ACK came back")


if __name__ == "__main__":
    main()
