"""The lockstep runner's clock: tick k is at k / TICK_RATE, so a run's times never drift from its tick count, and a
timed event lands on the tick of its time however long the run has been going."""

from __future__ import annotations

from dataclasses import replace

from sim.runner import Run
from sim.scenario import Event, load
from vehicle.app import DT


def test_a_run_ends_on_the_tick_of_its_duration():
    run = Run(load("open"), duration=20.0)
    run.run()
    t = run.trace.t
    assert len(t) == 1000 and t[-1] == run.t == 20.0  # a running float sum would end a hair short of 20
    assert t[0] == DT and all(abs(b - a - DT) < 1e-9 for a, b in zip(t, t[1:], strict=False))


def test_a_timed_event_lands_on_its_own_tick():
    """A stop at 61.34 s ends the run on tick 3067, at exactly that time (a running float sum strays from it)."""
    sc = load("open")
    run = Run(replace(sc, events=(Event(61.34, "stop"),)), duration=100.0)
    run.run()
    assert run.stopped and run.ticks == 3067 and run.t == 61.34
