"""The scripted operator's way home after a return: it picks the resume route up where the robot is."""

from __future__ import annotations

from sim.station_script import Leg

HOME = ((40.0, 0.0, 1.2), (-5.0, 0.0, 1.5))  # the tunnel's resume route: out of the bend, then home


def test_a_robot_the_return_brought_past_the_first_waypoint_drives_on_home():
    """At a weak radio the return brings the robot back to 25 m; driving to the 40 m waypoint first took it back
    into the dead stretch, and every policy then lost the link a second time, the script's doing."""
    leg = Leg(HOME)
    leg.join(25.0, 0.3)
    assert leg.index == 1


def test_a_robot_still_in_the_bend_goes_to_the_first_waypoint_first():
    leg = Leg(HOME)
    leg.join(45.0, 5.0)  # beyond the first waypoint: the way home is through it
    assert leg.index == 0
    leg.join(40.5, 1.0)  # beside it, not alongside the leg home
    assert leg.index == 0


def test_joining_never_goes_back_to_a_waypoint_already_passed():
    leg = Leg(((0.0, 0.0, 1.0), (10.0, 0.0, 1.0), (10.0, 10.0, 1.0)), index=2)
    leg.join(5.0, 0.0)  # alongside the first leg, already driven
    assert leg.index == 2


def test_a_robot_beside_a_leg_but_not_on_it_drives_to_the_next_waypoint_as_written():
    """building: resting in the room 1.9 m off the leg through the doorway, cutting over to that leg's end clipped
    the door frame; the waypoint before the doorway is there to be driven to."""
    leg = Leg(((35.0, 3.0, 0.5), (34.5, -0.8, 0.5), (-5.0, 0.0, 1.5)))
    leg.join(36.85, 2.6)
    assert leg.index == 0
