"""Lease enforcement and transition throughput on one core (docs/architecture.md §8: aim >= 200,000 checks/s in
CPython)."""

from __future__ import annotations

import time

from vehicle.lease import ExpireReason, LeaseBook, LeaseId, ServiceBlock

GCS = 255


def bench_checks(n: int = 300_000) -> float:
    book = LeaseBook().acquire(GCS, 190, 0.0).book
    e = book.epoch
    claims = [None, LeaseId(e, (0,)), LeaseId(e, (0, 0)), LeaseId(e, (1,)), LeaseId(e + 1, (0,))]
    senders = [GCS, GCS, GCS, GCS, 245]
    t0 = time.perf_counter()
    for k in range(n):
        book.check(senders[k % 5], claims[k % 5])
    return n / (time.perf_counter() - t0)


def bench_events(n: int = 30_000) -> float:
    """Full cycles: comms lost -> return block -> completed -> claim, each a transition with one event."""
    book = LeaseBook(plan=(ServiceBlock("rtl"),)).acquire(GCS, 190, 0.0).book
    events = 0
    t = 0.0
    t0 = time.perf_counter()
    for _ in range(n // 3):
        t += 10.0
        out = book.tick(t)  # COMMS_LOST
        out = out.book.finish(out.book.current.index, ExpireReason.COMPLETED, t)
        book = out.book.heard(GCS, t + 0.1)
        out2, _ = book.claim(GCS, book.epoch, 0, t + 0.1)  # NEWER_LEASE
        book = out2.book
        events += 3
    return events / (time.perf_counter() - t0)


def main() -> None:
    checks = bench_checks()
    events = bench_events()
    print(f"lease enforcement checks/s : {checks:12,.0f}   (aim 200,000: {checks / 200_000:.1f}x)")
    print(f"lease transitions events/s : {events:12,.0f}")


if __name__ == "__main__":
    main()
