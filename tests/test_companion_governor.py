"""The companion's speed governor for ArduPilot Rover (``vehicle.companion.governor``): the foreseen overshoot of the
autopilot's speed loop comes off the target; steady driving, stops and turns are sent as commanded; a loop that
follows its target without lag is soon left alone."""

from __future__ import annotations

import pytest

from vehicle.companion.governor import GAIN, LEAD, Governor


def test_steady_at_or_below_the_command_the_target_is_the_command():
    g = Governor()
    assert g.target(2.0, 2.0) == 2.0
    assert g.target(2.0, 1.2) == 2.0
    assert g.target(-2.0, -1.5) == -2.0  # backward alike


def test_an_excess_comes_off_the_target_gain_times_with_what_it_is_still_gaining():
    g = Governor()
    assert g.target(2.0, 2.2) == pytest.approx(2.0 - GAIN * 0.2)
    assert g.target(2.0, 2.1, accel=1.0) == pytest.approx(2.0 - GAIN * (0.1 + LEAD * 1.0))
    assert g.target(-2.0, -2.1, accel=-1.0) == pytest.approx(-(2.0 - GAIN * (0.1 + LEAD * 1.0)))
    assert g.target(2.0, 2.1, accel=-1.0) == pytest.approx(2.0 - GAIN * 0.1)  # falling back: the excess alone


def test_an_overshoot_coming_is_met_before_it_arrives():
    """Still below the command but gaining: the speed LEAD s ahead is past it, so the target drops now (the SITL's
    loop, which lags its target and overshoots it)."""
    g = Governor()
    assert g.target(2.0, 1.9, accel=1.0) == pytest.approx(2.0 - GAIN * (1.9 + LEAD - 2.0))
    assert g.target(2.0, 2.0, accel=0.5) < 2.0  # still gaining at the command: it does not slow at once


def test_a_loop_that_follows_its_target_at_once_is_left_alone_after_one_lowered_target():
    """A lowered target and the rover at once slowing below the command: no lag to foresee, and foresight would
    hold it under the command, braking and driving in turn. From then on only a real excess is governed."""
    g = Governor()
    assert g.target(1.0, 0.8, accel=3.0) < 1.0
    assert g.target(1.0, 0.5, accel=-3.0) == 1.0
    assert not g.foresee
    assert g.target(1.0, 0.8, accel=3.0) == 1.0
    assert g.target(1.0, 1.2) == pytest.approx(1.0 - GAIN * 0.2)


def test_a_dip_of_the_speed_near_the_command_keeps_the_foresight():
    """Steady at the command, the estimate's noise lowers a target now and then: the speed dipping a few cm/s after
    it is not a loop without lag, and the next overshoot is still foreseen."""
    g = Governor()
    assert g.target(2.0, 1.98, accel=0.4) < 2.0
    assert g.target(2.0, 1.95, accel=-0.3) == 2.0
    assert g.foresee


def test_the_target_never_reverses_the_rover():
    g = Governor()
    assert g.target(1.0, 2.5) == 0.0  # the approach speed from 2.5 m/s: a stop, never backward
    assert g.target(-1.0, -2.5) == 0.0


def test_stops_turns_in_place_and_reversals_are_sent_as_commanded():
    g = Governor()
    assert g.target(0.0, 2.0) == 0.0
    assert g.target(0.03, 2.0) == 0.03  # a creep: below MOVING
    assert g.target(-2.0, 1.0, accel=-1.0) == -2.0  # still rolling forward: the command is a reversal
