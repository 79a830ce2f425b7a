"""Fingerprints of fixed lockstep runs, the yardstick of the speed work: a faster tick must not change a single
lease event, true or estimated position, or MAVLink byte.

``python tests/golden_runs.py`` rewrites ``tests/golden/*.json``; do that only for a change that is meant to alter
behaviour, and say so in its commit.
"""

from __future__ import annotations

import hashlib
import json
import struct
import sys
from pathlib import Path

GOLDEN = Path(__file__).parent / "golden"
# (scenario, vehicle, seed, simulated seconds): both robots over different worlds, the benchmark's own run, and
# returns that go on past a dead zone (culvert) and turn in rooms (building)
CASES = [("tunnel", "rover", 1, None), ("warehouse", "legged", 2, None), ("tunnel", "legged", 1, None),
         ("culvert", "rover", 3, None), ("building", "legged", 4, None)]


def _digest(values) -> str:
    """SHA-256 of a sequence of floats packed as IEEE doubles: any change in any bit of any tick shows."""
    h = hashlib.sha256()
    for v in values:
        h.update(struct.pack("<d", float(v)))
    return h.hexdigest()


def fingerprint(scenario: str, vehicle: str, seed: int, duration: float | None) -> dict:
    """Metrics (without ``real_time_factor``, the one wall-clock figure) and digests of the per-tick trace and the
    operator station's .tlog."""
    from sim import metrics
    from sim.runner import Run
    from sim.scenario import load

    run = Run(load(scenario), vehicle, seed, duration=duration).run()
    m = metrics.compute(run)
    m.pop("real_time_factor", None)
    tr = run.trace
    return {
        "metrics": json.loads(json.dumps(m)),
        "ticks": len(tr.t),
        "true": _digest(c for p in tr.true for c in p),
        "est": _digest(c for p in tr.est for c in p),
        "cmd": _digest(c for p in tr.cmd for c in p),
        "states": hashlib.sha256(bytes(str(tr.state + tr.holder + tr.index), "ascii")).hexdigest(),
        "tlog": hashlib.sha256(b"".join(run.tlog)).hexdigest(),
    }


def path_of(scenario: str, vehicle: str, seed: int) -> Path:
    return GOLDEN / f"{scenario}-{vehicle}-{seed}.json"


def main() -> int:
    GOLDEN.mkdir(exist_ok=True)
    for sc, kind, seed, dur in CASES:
        p = path_of(sc, kind, seed)
        p.write_text(json.dumps(fingerprint(sc, kind, seed, dur), indent=1, sort_keys=True) + "\n", encoding="utf-8")
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
