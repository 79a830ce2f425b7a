"""The path follower: which way it drives, when it turns in place, and that it never swings a U-turn with speed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.robots import make_robot
from sim.world import World
from vehicle.app import velocity_to_command
from vehicle.navigation import FollowerConfig, Path, follow

NORTH = 0.0
EAST = math.pi / 2


def _line(*points) -> Path:
    return Path(np.array(points, dtype=float))


def test_a_route_behind_the_robot_is_driven_in_reverse():
    cmd = follow(_line((0, 0), (-20, 0)), 0.0, 0.0, NORTH, 0.0, 1.0)
    assert cmd.reverse
    assert cmd.speed == pytest.approx(-1.0, abs=0.05)
    assert abs(cmd.yaw_rate) < 0.05  # straight back, no swing


def test_a_route_ahead_is_driven_forward():
    cmd = follow(_line((0, 0), (20, 0)), 0.0, 0.0, NORTH, 0.0, 1.0)
    assert not cmd.reverse and cmd.speed == pytest.approx(1.0, abs=0.05)


def test_the_end_of_a_route_the_way_goes_on_past_is_not_eased_into():
    """A return arriving at its target with the link still down goes on back along the trail: the target is then a
    waypoint, and slowing for it only to speed up again lost a second to every baseline."""
    path = _line((0, 0), (2.0, 0))
    stop = follow(path, 0.5, 0.0, NORTH, 0.0, 2.0)
    through = follow(path, 0.5, 0.0, NORTH, 0.0, 2.0, through=True)
    assert stop.speed < 1.3  # eases into a stop
    assert through.speed == pytest.approx(2.0, abs=0.05)


def test_a_gentle_arc_is_driven_at_speed_and_a_tight_one_at_the_speed_the_robot_can_turn_it():
    """No cos(heading error) slow-down on arcs the robot can turn at its cruise speed (it cost a walking robot a
    quarter second at every doorway, and its P95 time to link against SmartRTL in the building); an arc tighter
    than max_yaw_rate allows at speed is driven at the speed whose turn rate it is, so the robot stays on it."""
    cfg = FollowerConfig()
    gentle = follow(_line((0, 0.3), (20, 0.3)), 0.0, 0.0, NORTH, 0.0, 0.6, cfg)  # walking, 0.3 m off the line
    assert gentle.speed == pytest.approx(0.6)  # cos(heading error) would have asked 0.56
    slow_turner = FollowerConfig(max_yaw_rate=1.0)
    tight = follow(_line((0, 0.6), (20, 0.6)), 0.0, 0.0, NORTH, 0.0, 2.0, slow_turner)  # 2 m/s, 0.6 m off the line
    assert 1.0 < tight.speed < 1.9
    assert abs(tight.yaw_rate) == pytest.approx(1.0, rel=1e-6)  # as fast as that arc can be turned


@pytest.mark.parametrize("reverse", [False, True])
def test_a_large_heading_error_turns_in_place_before_driving(reverse):
    # the route runs east, the robot faces north: 90 degrees off, whichever end leads
    cmd = follow(_line((0, 0), (0, 20)), 0.0, 0.0, NORTH, 0.0, 1.0, reverse=reverse)
    assert cmd.speed == 0.0
    assert cmd.reverse is reverse  # the sideways route keeps the direction it had (hysteresis)
    # forward it turns its nose east (clockwise, positive yaw rate), backward its tail
    assert cmd.yaw_rate == pytest.approx(1.5 if not reverse else -1.5)


def test_backing_round_a_bend_steers_with_the_tail():
    # facing north with the route behind and bending to the east: the tail must swing east, the nose west
    path = _line((0, 0), (-2, 0), (-4, 2))
    cmd = follow(path, 0.0, 0.0, math.radians(-15.0), 0.0, 1.0, reverse=True)
    assert cmd.reverse and cmd.speed < 0
    x, y, yaw, progress, reverse = 0.0, 0.0, math.radians(-15.0), 0.0, True
    for _ in range(400):
        cmd = follow(path, x, y, yaw, progress, 1.0, FollowerConfig(), reverse)
        if cmd.arrived:
            break
        progress, reverse = cmd.progress, cmd.reverse
        yaw += cmd.yaw_rate * 0.02
        x += cmd.speed * math.cos(yaw) * 0.02
        y += cmd.speed * math.sin(yaw) * 0.02
        assert cmd.speed <= 0.0
    assert cmd.arrived and math.hypot(x + 4, y - 2) <= 1.0


def test_the_follower_never_drives_with_a_large_heading_error():
    """The U-turn that hit the adit wall: forward speed while the heading was 60 degrees and more off."""
    rng = np.random.default_rng(1)
    cfg = FollowerConfig()
    for _ in range(500):
        pts = np.cumsum(rng.uniform(-3, 3, size=(5, 2)), axis=0)
        yaw = float(rng.uniform(-math.pi, math.pi))
        cmd = follow(Path(pts), float(pts[0, 0]), float(pts[0, 1]), yaw, 0.0, 1.0, cfg, bool(rng.integers(2)))
        if cmd.arrived or cmd.speed == 0.0:
            continue
        tx, ty = Path(pts).at(cmd.progress + max(cfg.lookahead_min, cfg.lookahead_gain))
        travel = yaw + (math.pi if cmd.speed < 0 else 0.0)
        err = abs((math.atan2(ty - pts[0, 1], tx - pts[0, 0]) - travel + math.pi) % (2 * math.pi) - math.pi)
        assert err <= cfg.turn_in_place + 1e-9


def test_a_velocity_target_far_off_the_heading_turns_in_place_first():
    """Teleop after a return: the robot faces into the culvert, the operator asks to go out. No swinging arc."""
    for off in (70.0, 120.0, 175.0):  # well to the side, behind
        a = math.radians(off)
        speed, turn = velocity_to_command(math.cos(a), math.sin(a), None, NORTH)
        assert speed == 0.0 and turn > 0.5
    a = math.radians(30.0)  # 30 degrees off: within the threshold, drive the share along the heading and turn
    speed, turn = velocity_to_command(math.cos(a), math.sin(a), None, NORTH)
    assert speed == pytest.approx(math.cos(a)) and turn > 0


@pytest.mark.parametrize("kind", ["rover", "legged"])
def test_both_robots_drive_backward(kind):
    world = World(())
    robot = make_robot(kind, world, 0.0, 0.0, 0.0, np.random.default_rng(0))
    for _ in range(200):
        robot.command(-0.5, 0.0)
        robot.before_step(0.02)
        world.step(0.02)
        robot.after_step(0.02)
    assert robot.true_speed == pytest.approx(-0.5, abs=0.02)
    assert robot.pose[0] < -1.5
    if kind == "legged":
        assert robot.steps > 0  # it walked (trotted) backward, touchdown by touchdown
