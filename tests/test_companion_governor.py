"""The companion's speed governor for ArduPilot Rover (``vehicle.companion.governor``): the foreseen overshoot of the
autopilot's speed loop comes off the target; steady driving, stops and turns are sent as commanded."""

from __future__ import annotations

import pytest

from vehicle.companion.governor import GAIN, LEAD, governed


def test_at_or_below_the_command_the_target_is_the_command():
    assert governed(2.0, 2.0) == 2.0
    assert governed(2.0, 1.2) == 2.0
    assert governed(-2.0, -1.5) == -2.0  # backward alike


def test_a_measured_excess_comes_off_the_target_gain_times():
    assert governed(2.0, 2.2) == pytest.approx(2.0 - GAIN * 0.2)
    assert governed(-2.0, -2.2) == pytest.approx(-(2.0 - GAIN * 0.2))


def test_an_overshoot_coming_is_met_before_it_arrives():
    """Still below the command but accelerating: the speed LEAD s ahead is past it, so the target drops now."""
    assert governed(2.0, 1.9, accel=1.0) == pytest.approx(2.0 - GAIN * (1.9 + LEAD - 2.0))
    assert governed(2.0, 1.9, accel=0.0) == 2.0
    assert governed(2.0, 2.1, accel=-1.0) == 2.0  # slowing back toward it: nothing foreseen past it


def test_the_target_never_reverses_the_rover():
    assert governed(1.0, 2.5) == 0.0  # the approach speed from 2.5 m/s: a stop, never backward
    assert governed(-1.0, -2.5) == 0.0


def test_stops_turns_in_place_and_reversals_are_sent_as_commanded():
    assert governed(0.0, 2.0) == 0.0
    assert governed(0.03, 2.0) == 0.03  # a creep: below MOVING
    assert governed(-2.0, 1.0) == -2.0  # the rover still rolls forward: the command is a reversal, not a speed
