"""Robot models, sensors, estimator and path following in simulation (no MAVLink, no radio)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim import scenario
from sim.drive import Rig
from sim.robots import Legged, Rover, make_robot
from sim.world import World
from vehicle.returning import Target, plan_route


@pytest.mark.parametrize("name", ["loop", "tunnel"])
@pytest.mark.parametrize("vehicle", ["rover", "legged"])
def test_follows_the_reversed_route_end_to_end_without_a_collision(name, vehicle):
    s = scenario.load(name)
    rig = Rig(s, vehicle)
    assert rig.drive_route()
    p = rig.estimator.pose
    route = plan_route(rig.trail, (p.x, p.y), Target.ORIGIN, 1000.0, link_lost=False)
    assert route.length > 40.0
    assert rig.drive(route.points[1:], 1.0, timeout=400.0)
    x, y, _ = rig.robot.pose
    assert math.hypot(x - s.start[0], y - s.start[1]) < 2.5
    assert rig.world.collisions == 0


def test_walls_are_real_collisions_and_are_counted():
    from sim.world import Wall

    world = World((Wall(((5.0, -5.0), (5.0, 5.0)), 0.5, 10.0),))
    robot = Rover(world, 0.0, 0.0, 0.0, np.random.default_rng(0))
    for _ in range(400):
        robot.command(1.5, 0.0)
        robot.before_step(0.02)
        world.step(0.02)
        robot.after_step(0.02)
    assert robot.pose[0] < 5.0 - 0.25 - 0.35 + 0.05  # it stops at the wall, not inside it
    assert world.collisions == 1  # one contact, however long it lasts
    assert world.attenuation_db((0.0, 0.0), (10.0, 0.0)) == 10.0
    assert world.attenuation_db((0.0, 0.0), (0.0, 3.0)) == 0.0


@pytest.mark.parametrize("kind", ["rover", "legged"])
def test_the_pose_is_where_the_body_is_after_every_step(kind):
    """The pose is read back once per physics step; it must never lag the body (against a wall, turning)."""
    from sim.world import Wall

    world = World((Wall(((3.0, -5.0), (3.0, 5.0)), 0.5, 10.0),))
    robot = make_robot(kind, world, 0.0, 0.0, 0.3, np.random.default_rng(0))
    assert robot.pose == (0.0, 0.0, 0.3)
    for k in range(300):
        robot.command(1.5, 0.6 if k % 100 < 30 else 0.0)
        robot.before_step(0.02)
        if not world.space.shape_query(robot.shape):  # in the open: the commanded velocity along the pose's yaw
            yaw = robot.pose[2]
            assert robot.body.velocity == (robot.speed * math.cos(yaw), robot.speed * math.sin(yaw))
        world.step(0.02)
        robot.after_step(0.02)
        x, y = robot.body.position
        assert robot.pose == (x, y, robot.body.angle)
    assert world.collisions >= 1


def _clamp(v: float, lo: float, hi: float) -> float:
    """The clamp the physics step writes out, by the builtins (ties, signed zeros and NaN decide alike)."""
    return max(lo, min(hi, v))


def _approach(current: float, target: float, max_step: float) -> float:
    """The rate limit the physics step writes out: ``current`` moved toward ``target`` by at most ``max_step``."""
    return current + max(-max_step, min(max_step, target - current))


@pytest.mark.parametrize("kind", ["rover", "legged"])
def test_command_and_step_limits_are_clamp_and_approach(kind):
    """``command`` and ``before_step`` write out ``_clamp`` and ``_approach`` for speed: they must give the very
    same floats, over commands beyond the limits both ways, small steps and reversals."""

    def bits(*values: float) -> list[str]:  # every bit, the sign of a zero too
        return [v.hex() for v in values]

    world = World(())
    robot = make_robot(kind, world, 0.0, 0.0, 0.0, np.random.default_rng(0))
    rng = np.random.default_rng(3)
    for k in range(400):
        cmd = (float(rng.normal(0.0, 3.0)), float(rng.normal(0.0, 2.5))) if k % 7 else (0.0, -0.0)
        robot.command(*cmd)
        assert bits(robot.cmd_speed, robot.cmd_yaw_rate) == bits(
            _clamp(cmd[0], -robot.max_speed, robot.max_speed), _clamp(cmd[1], -robot.max_yaw_rate, robot.max_yaw_rate))
        speed, yaw_rate = robot.speed, robot.yaw_rate
        target = robot.limits(robot.cmd_speed, robot.cmd_yaw_rate)
        robot.before_step(0.02)
        assert bits(robot.speed, robot.yaw_rate) == bits(_approach(speed, target[0], robot.max_accel * 0.02),
                                                         _approach(yaw_rate, target[1], robot.max_yaw_accel * 0.02))
        world.step(0.02)
        robot.after_step(0.02)


def test_legged_limits_are_the_clamps_they_write_out():
    """``Legged.limits`` writes out ``_clamp`` and ``max(0.3, ...)``: the very same floats and step frequency as
    the helpers give, for speeds and rates past every limit, at the limits, signed zeros and NaN."""

    def reference(robot, speed: float, yaw_rate: float) -> tuple[float, float, float]:
        s = robot.spec
        step_hz = _clamp(2.0 * abs(speed) / robot._stride_divisor, s.min_step_hz, s.max_step_hz)
        cap = robot.max_stride * step_hz / 2.0
        speed = _clamp(speed, -cap, cap)
        turn_cap = s.max_yaw_rate * max(0.3, 1.0 - abs(speed) / robot._speed_divisor)
        return speed, _clamp(yaw_rate, -turn_cap, turn_cap), step_hz

    robot = make_robot("legged", World(()), 0.0, 0.0, 0.0, np.random.default_rng(0))
    rng = np.random.default_rng(5)
    edges = [0.0, -0.0, math.nan, robot.max_speed, -robot.max_speed, robot.max_speed * 0.7 + 1e-6, 5.0, -5.0]
    cases = [(a, b) for a in edges for b in edges + [robot.spec.max_yaw_rate, -robot.spec.max_yaw_rate]]
    cases += [(float(rng.normal(0.0, 1.5)), float(rng.normal(0.0, 1.5))) for _ in range(300)]
    for speed, yaw_rate in cases:
        got = robot.limits(speed, yaw_rate)
        assert [v.hex() for v in (*got, robot.step_hz)] == [v.hex() for v in reference(robot, speed, yaw_rate)]


def point_in_polygon(x: float, y: float, poly: tuple[tuple[float, float], ...]) -> bool:
    """The even-odd crossing test over the polygon's vertices, as the world ran it before it prepared edges."""
    inside = False
    n = len(poly)
    for i in range(n):
        (x1, y1), (x2, y2) = poly[i], poly[(i + 1) % n]
        if (y1 > y) != (y2 > y) and x < (x2 - x1) * (y - y1) / (y2 - y1) + x1:
            inside = not inside
    return inside


def test_gps_denied_is_point_in_polygon_over_every_zone():
    """The world tests its denied zones over edges worked out once: the same answer as the polygon test over its
    vertices (``point_in_polygon`` here), on and around the vertices and edges too."""
    zones = (((3.0, -3.0), (42.0, -3.0), (62.0, 16.0), (56.0, 22.0), (38.0, 3.0), (3.0, 3.0)),
             ((-10.0, -10.0), (-4.0, -10.0), (-4.0, -4.0)))
    world = World((), zones)
    points = [(x * 0.5, y * 0.5) for x in range(-30, 130) for y in range(-30, 50)]
    points += [p for zone in zones for p in zone]
    got = [world.gps_denied(x, y) for x, y in points]
    assert got == [any(point_in_polygon(x, y, z) for z in zones) for x, y in points]
    assert 100 < sum(got) < len(points)


def test_legged_speed_is_bounded_by_stride_and_step_frequency():
    world = World(())
    robot = Legged(world, 0.0, 0.0, 0.0, np.random.default_rng(0))
    s = robot.spec
    reach = math.sqrt((s.upper_leg + s.lower_leg) ** 2 - s.hip_height**2)
    top = 2 * reach * s.stride_margin * s.max_step_hz / 2
    for _ in range(500):
        robot.command(5.0, 0.0)
        robot.before_step(0.02)
        world.step(0.02)
        robot.after_step(0.02)
    assert robot.true_speed <= top + 1e-6
    assert robot.true_speed > 0.9 * top
    assert robot.step_hz == s.max_step_hz
    assert robot.steps > 0  # touchdowns happened, each with its own slip
    fx, _ = zip(*robot.feet, strict=True)
    assert max(fx) > robot.pose[0]  # front feet placed ahead of the body


def test_estimator_beats_raw_fixes_in_the_open():
    s = scenario.load("open")
    rig = Rig(s, "rover")
    rig.drive(np.array([[80.0, 0.0]]), 1.5, timeout=200.0)
    raw = float(np.sqrt(np.mean(np.square(rig.log.fix_err))))
    assert rig.log.rmse() < 0.6 * raw


def test_dead_reckoning_drift_is_bounded_and_covariance_grows_across_a_denied_stretch():
    s = scenario.load("tunnel")
    rig = Rig(s, "legged")
    rig.drive(np.array([[38.0, 0.0]]), 1.0, timeout=200.0)
    inside = [k for k, (x, y) in enumerate(rig.log.true) if rig.world.gps_denied(x, y)]
    assert len(inside) > 1000
    std = np.array(rig.log.std)[inside]
    assert std[-1] > 2 * std[0]  # honestly growing uncertainty
    err = np.hypot(*(np.array(rig.log.true)[inside] - np.array(rig.log.est)[inside]).T)
    assert err.max() < 2.0  # over ~35 m without a fix
    assert err.max() < 3 * std.max()  # and the filter knows roughly how wrong it is


def test_sensors_and_runs_are_deterministic():
    a, b = Rig(scenario.load("loop"), "legged"), Rig(scenario.load("loop"), "legged")
    for rig in (a, b):
        rig.drive(np.array([[20.0, 0.0]]), 1.0, timeout=60.0)
    assert a.log.est == b.log.est and a.log.true == b.log.true
