"""``make fuzz``: the checksum-aware fuzzer of tests/fuzzing.py for longer than the suite can afford.

    python -m tests.fuzz_main [--frames N] [--seconds S] [--seed K]

Runs fresh vehicles with seeds K, K+1, ... (100,000 frames each) until N frames or S seconds, prints the frames
and frames/s, and exits 1 on the first crash or state change, printing the frame that caused it (hex) and the
seed that reproduces it.
"""

from __future__ import annotations

import argparse
import sys
import time

from tests.fuzzing import MESSAGES, Fuzzer

CHUNK = 100_000


def _positive(kind):
    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not v > 0:
            raise argparse.ArgumentTypeError(f"{text!r} must be positive")
        return v
    return parse


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="fuzz_main", description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=_positive(int), default=1_000_000, help="stop after this many frames")
    p.add_argument("--seconds", type=_positive(float), default=float("inf"), help="or after this many seconds")
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)
    start = time.perf_counter()
    total, seed, reached = 0, args.seed, set()
    while total < args.frames and time.perf_counter() - start < args.seconds:
        rep = Fuzzer(seed).run(min(CHUNK, args.frames - total))
        total += rep.frames
        reached |= rep.reached
        elapsed = time.perf_counter() - start
        print(f"seed {seed}: {rep.frames} frames ({rep.owner_frames} from the owner, {rep.garbled} garbled); "
              f"total {total} frames in {elapsed:.1f} s, {total / elapsed:,.0f} frames/s", flush=True)
        if rep.crashes or rep.state_changes:
            for line in (rep.crashes + rep.state_changes)[:5]:
                print(f"FAIL (seed {seed}): {line}", file=sys.stderr)
            return 1
        seed += 1
    missing = sorted(set(MESSAGES) - reached)
    if missing:
        print(f"FAIL: message ids never reached: {missing}", file=sys.stderr)
        return 1
    elapsed = time.perf_counter() - start
    print(f"fuzz: {total} frames, {total / elapsed:,.0f} frames/s, every one of {len(MESSAGES)} message ids "
          f"reached, no crash, no state change by a non-owner")
    return 0


if __name__ == "__main__":
    sys.exit(main())
