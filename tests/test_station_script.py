"""The one root of the scripted operators (``sim.station_script.ScriptedStation``): every operator, whatever it
flies, counts a loss against the place it was driving toward, gives a place up after ``attempts`` losses, and
picks the way home up where the robot is after a return (unless it drives it as written)."""

from __future__ import annotations

import pytest

from sim.firmware.applet_operator import AppletOperator
from sim.firmware.companion_operator import CompanionOperator
from sim.firmware.operator import FirmwareOperator
from sim.operator import Operator
from sim.px4.companion_operator import PX4CompanionOperator
from sim.px4.operator import PX4Operator
from sim.station_script import ScriptedStation

ROUTE = [(0.0, 0.0, 1.0), (10.0, 0.0, 1.0), (20.0, 0.0, 1.0)]
HOME = [(20.0, 0.0, 1.0), (10.0, 0.0, 1.0), (0.0, 0.0, 1.0)]


@pytest.mark.parametrize("kind", [Operator, FirmwareOperator, AppletOperator, CompanionOperator, PX4Operator,
                                  PX4CompanionOperator])
def test_every_scripted_operator_has_the_one_root(kind):
    assert issubclass(kind, ScriptedStation)


def test_a_place_is_given_up_after_its_attempts_and_counted_once_per_loss():
    s = ScriptedStation(ROUTE, HOME, attempts=2)
    s.heading_to = (10.0, 0.0)
    s._lost_on_the_way()
    s.heading_to = None
    s._lost_on_the_way()  # a later sign with no place named keeps the place named before
    s._count_loss()
    s._count_loss()  # nothing more to count until the next loss
    assert s.losses == {(10.0, 0.0): 1} and not s._given_up((10.0, 0.0))
    s.heading_to = (10.0, 0.0)
    s._lost_on_the_way()
    s._count_loss()
    assert s._given_up((10.0, 0.0)) and not s._given_up((20.0, 0.0))


@pytest.mark.parametrize(("rejoin", "phase", "index"), [(True, "resuming", 2), (False, "resuming", 0),
                                                         (True, "driving", 0)])
def test_the_way_home_is_picked_up_where_the_robot_is_only_on_the_way_home(rejoin, phase, index):
    s = ScriptedStation(ROUTE, HOME, rejoin=rejoin)
    s.phase = phase
    s._pick_up_way_home((4.0, 0.2))  # on the last leg of the way home
    assert s.resume.index == index
