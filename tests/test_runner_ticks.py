"""The lockstep runner's clock: tick k is at k / TICK_RATE, exactly the time the running sum rounded to 9 decimals
every tick gave, so traces, metrics and .tlog stamps did not move when the round went."""

from __future__ import annotations

from sim.runner import TICK_RATE, Run
from sim.scenario import load
from vehicle.app import DT


def test_tick_time_is_the_rounded_running_sum_for_days_of_ticks():
    t = 0.0
    for k in range(1, 1_000_001):  # 5.5 h of simulated time
        t = round(t + DT, 9)
        assert k / TICK_RATE == t, k


def test_a_run_stamps_its_ticks_with_that_clock():
    run = Run(load("open"), duration=20.0)
    run.run()
    t, expected = 0.0, []
    for _ in range(len(run.trace.t)):
        t = round(t + DT, 9)
        expected.append(t)
    assert len(expected) == 1000
    assert run.trace.t == expected
    assert run.t == expected[-1]
