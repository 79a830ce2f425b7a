"""``returnlink sim sweep``: spec -> pending trials -> executor -> store -> summary and report.

The imperative shell of the campaign package: the clock, the terminal and the files are here, the decisions in
``spec``, ``trial`` and ``store``.
"""

from __future__ import annotations

import sys
import time

from sim.campaign import report
from sim.campaign.spec import Spec
from sim.campaign.store import Store, format_table, summary
from sim.campaign.trial import run_trial


class Progress:
    """A bar over trials in the style of ``sim run``'s: redrawn on a terminal, a line every few percent in a log."""

    def __init__(self, total: int, stream=None) -> None:
        self.total, self.done, self.errors = total, 0, 0
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self.shown = -1
        self.t0 = time.monotonic()

    def step(self, row: dict) -> None:
        self.done += 1
        self.errors += row.get("status") == "error"
        pct = 100 * self.done // max(1, self.total)
        if pct == self.shown or (pct % (2 if self.tty else 10) and self.done != self.total):
            return
        self.shown = pct
        bar = "#" * (pct // 4) + "." * (25 - pct // 4)
        rate = self.done / max(1e-9, time.monotonic() - self.t0) * 3600
        print(f"\r  [{bar}] {pct:3d}%  {self.done}/{self.total} trials, {self.errors} errors, {rate:,.0f}/h",
              end="" if self.tty else "\n", file=self.stream, flush=True)

    def close(self) -> None:
        if self.tty and self.shown >= 0:
            print(file=self.stream)


def run_sweep(spec: Spec, store: Store, executor, fn=run_trial, progress: bool = True) -> Store:
    """Run every trial of ``spec`` not already finished in ``store``, store the rows as they come, then write
    summary.csv and report.md. Ctrl-C keeps everything finished so far (the store is flushed on the way out)."""
    out = store.out
    todo = store.pending(spec.trials)
    done = len(spec.trials) - len(todo)
    if todo:
        print(f"returnlink: {len(spec.trials)} trials in {spec.file}, {done} already done in {out}, {len(todo)} to "
              f"run on {executor.where}, {executor.workers} at a time", file=sys.stderr)
    else:
        print(f"returnlink: all {len(spec.trials)} trials of {spec.file} already done in {out}", file=sys.stderr)
    bar = Progress(len(todo)) if progress and todo else None
    try:
        for row in executor.map(todo, spec.timeout_s, fn):
            store.add(row)
            if bar is not None:
                bar.step(row)
    finally:
        if bar is not None:
            bar.close()
        store.flush()
    store.write_summary()
    report.write(out, store.rows.values())
    return store


def print_summary(store: Store) -> None:
    rows = summary(store.rows.values())
    print(format_table(rows, report.TABLE_COLUMNS))
    print(f"  wrote {store.path}, {store.out / 'summary.csv'}, {store.out / 'report.md'}")
