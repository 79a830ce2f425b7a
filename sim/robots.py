"""Robot models on pymunk bodies: a differential-drive rover and a trotting quadruped.

Both take the same command (forward speed, yaw rate) and report the same things (true pose for scoring, an
odometry speed for the estimator), so the vehicle software cannot tell them apart except by their limits.
The body is dynamic, so walls stop it and the world counts the contacts; the commanded velocity is applied each
step (a velocity-controlled base, as real robots expose).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pymunk
from pymunk._chipmunk_cffi import ffi, lib

from sim.world import ROBOT, ROBOT_FILTER, World

# pymunk's Body routes every attribute write through a Python ``__setattr__`` and then a Python property setter
# before the chipmunk call: the tick makes that very chipmunk call on the body's handle (the same doubles set,
# a third of the cost). Its getters wrap chipmunk's vector in a new Vec2d: ``after_step`` reads chipmunk's own.
_SET_VELOCITY, _SET_ANGULAR_VELOCITY = lib.cpBodySetVelocity, lib.cpBodySetAngularVelocity
_GET_POSITION, _GET_VELOCITY, _GET_ANGLE = lib.cpBodyGetPosition, lib.cpBodyGetVelocity, lib.cpBodyGetAngle


_NULL = ffi.NULL


def normal_draws(rng: np.random.Generator, block: int = 1024) -> Iterator[float]:
    """``rng.standard_normal()`` again and again: the same floats in the same order (numpy fills an array with the
    very draw it makes for a scalar), fetched a block at a time, as a scalar draw costs ten times a ``next``. Only
    for a stream nothing else draws from: the generator runs up to a block ahead. Nothing is drawn before the
    first ``next``, so draws made from ``rng`` before that come first, as before."""
    while True:
        yield from rng.standard_normal(block).tolist()


class Robot:
    kind = "robot"
    mav_type = 10  # MAV_TYPE_GROUND_ROVER

    def __init__(self, world: World, x: float, y: float, yaw: float, rng: np.random.Generator, radius: float,
                 max_speed: float, max_accel: float, max_yaw_rate: float, max_yaw_accel: float) -> None:
        self.rng = rng
        # the physics noise: only standard normals, drawn from here once the robot is built
        self.normal = normal_draws(rng).__next__
        self.max_speed, self.max_accel = max_speed, max_accel
        self.max_yaw_rate, self.max_yaw_accel = max_yaw_rate, max_yaw_accel
        self.body = pymunk.Body(10.0, math.inf)
        self.body.position = (x, y)
        self.body.angle = yaw
        self.shape = pymunk.Circle(self.body, radius)
        self.shape.collision_type = ROBOT
        self.shape.filter = ROBOT_FILTER  # collides as before; lines of sight for the radio pass through it
        self.shape.friction = 0.3
        world.space.add(self.body, self.shape)
        self.space = world.space
        # chipmunk's handles of the body, its shape and the space, for the calls of every physics step
        self._body, self._shape, self._space = self.body._body, self.shape._shape, self.space._space
        # only a model with limits of its own pays a call for them each step
        self._limited = type(self).limits is not Robot.limits
        self.cmd_speed = 0.0
        self.cmd_yaw_rate = 0.0
        self.speed = 0.0  # commanded-after-limits forward speed
        self.yaw_rate = 0.0
        self.odometer = 0.0
        self.true_speed = 0.0
        self.accel = 0.0  # true forward acceleration of the body (what an accelerometer feels), m/s^2
        # true (x, y, yaw) as of the last ``after_step``, for scoring: only a physics step moves the body, and the
        # sensors, the runner and the gait read it several times a tick, so it is kept rather than asked of pymunk
        # (and a plain attribute, not a property: set by the physics step alone)
        self.pose = (float(x), float(y), float(self.body.angle))
        # the cosine and sine of that pose's yaw: ``after_step`` needs them for the body's forward speed and the
        # next ``before_step`` for the commanded velocity, of the very same angle, so they are worked out once
        self._cos, self._sin = math.cos(self.pose[2]), math.sin(self.pose[2])

    def command(self, speed: float, yaw_rate: float) -> None:
        # ``_clamp(speed, -max_speed, max_speed)`` and the same for the rate, written out: the vehicle commands
        # every tick, and a helper's call costs more than its two comparisons
        hi = self.max_speed
        speed = speed if speed < hi else hi
        self.cmd_speed = speed if speed > -hi else -hi
        hi = self.max_yaw_rate
        yaw_rate = yaw_rate if yaw_rate < hi else hi
        self.cmd_yaw_rate = yaw_rate if yaw_rate > -hi else -hi

    def limits(self, speed: float, yaw_rate: float) -> tuple[float, float]:
        """Extra model-specific limits (the quadruped's stride and step frequency)."""
        return speed, yaw_rate

    def before_step(self, dt: float) -> None:
        if self._limited:
            speed, yaw_rate = self.limits(self.cmd_speed, self.cmd_yaw_rate)
        else:
            speed, yaw_rate = self.cmd_speed, self.cmd_yaw_rate
        # ``_approach`` of the speed and of the rate toward the command, written out (the same operations in the
        # same order): the physics step runs every tick, and a helper's call costs more than its arithmetic
        current, step = self.speed, self.max_accel * dt
        d = speed - current
        d = d if d < step else step
        speed = self.speed = current + (d if d > -step else -step)
        current, step = self.yaw_rate, self.max_yaw_accel * dt
        d = yaw_rate - current
        d = d if d < step else step
        yaw_rate = self.yaw_rate = current + (d if d > -step else -step)
        vx, vy = speed * self._cos, speed * self._sin
        # a velocity-controlled base pushes against a wall but cannot drive into it: drop the inward component.
        # Whether it touches anything is chipmunk's shape query without a callback, so pymunk builds no result
        # list and makes no Python call per hit: ``bool(space.shape_query(shape))`` (the world has no sensor
        # shapes) at a fraction of its cost, and most ticks the robot touches nothing
        if lib.cpSpaceShapeQuery(self._space, self._shape, _NULL, _NULL):
            for hit in self.space.shape_query(self.shape):
                if hit.shape is None or hit.shape.body is self.body:
                    continue
                n = hit.contact_point_set.normal  # from our shape towards the other one
                into = vx * n.x + vy * n.y
                if into > 0:
                    vx, vy = vx - into * n.x, vy - into * n.y
        _SET_VELOCITY(self._body, (vx, vy))
        _SET_ANGULAR_VELOCITY(self._body, yaw_rate)

    def after_step(self, dt: float) -> None:
        body = self._body
        p, v, a = _GET_POSITION(body), _GET_VELOCITY(body), _GET_ANGLE(body)
        x, y, vx, vy = p.x, p.y, v.x, v.y
        self.pose = (x, y, a)
        c = self._cos = math.cos(a)
        s = self._sin = math.sin(a)
        speed = vx * c + vy * s
        self.accel = (speed - self.true_speed) / dt
        self.true_speed = speed
        self.odometer += abs(speed) * dt

    def odometry_speed(self, dt: float) -> float:
        raise NotImplementedError


@dataclass(frozen=True)
class RoverSpec:
    radius: float = 0.35
    max_speed: float = 2.0
    max_accel: float = 1.5
    max_yaw_rate: float = 1.8
    max_yaw_accel: float = 6.0
    wheel_scale_error: float = 0.02  # calibration bias of the wheel radius
    wheel_noise: float = 0.03  # m/s
    slip_std: float = 0.02


class Rover(Robot):
    """Differential drive / unicycle with acceleration and turn-rate limits; wheel odometry with scale bias and
    slip that grows with turning."""

    kind = "rover"
    mav_type = 10

    def __init__(self, world: World, x: float, y: float, yaw: float, rng: np.random.Generator,
                 spec: RoverSpec = RoverSpec()) -> None:
        super().__init__(world, x, y, yaw, rng, spec.radius, spec.max_speed, spec.max_accel, spec.max_yaw_rate,
                         spec.max_yaw_accel)
        self.spec = spec
        self.scale = 1.0 + rng.normal(0.0, spec.wheel_scale_error)

    def odometry_speed(self, dt: float) -> float:
        s = self.spec
        slip = s.slip_std * (1.0 + abs(self.yaw_rate)) * self.normal()
        # wheels report the commanded wheel speed: against a wall they spin while the body does not move
        return self.speed * self.scale * (1.0 + slip) + s.wheel_noise * self.normal()


@dataclass(frozen=True)
class LeggedSpec:
    radius: float = 0.4
    hip_height: float = 0.32  # m, standing
    upper_leg: float = 0.22
    lower_leg: float = 0.22
    max_step_hz: float = 2.5  # step frequency limit of a trot
    min_step_hz: float = 1.2
    stride_margin: float = 0.85  # fraction of the geometric reach used
    body_half_length: float = 0.3
    body_half_width: float = 0.12
    max_yaw_rate: float = 1.2
    max_accel: float = 1.2
    max_yaw_accel: float = 4.0
    slip_std: float = 0.06  # per-step foot slip, fraction of the step
    leg_odo_noise: float = 0.04


class Legged(Robot):
    """A quadruped trot: diagonal leg pairs alternate stance and swing. The leg geometry bounds the stride (a foot
    can reach sqrt((l1 + l2)^2 - h^2) ahead of or behind its hip), the step-frequency limit bounds the speed, and
    every touchdown slips a little, which is what the leg odometry gets wrong."""

    kind = "legged"
    mav_type = 46  # MAV_TYPE_GROUND_QUADRUPED

    def __init__(self, world: World, x: float, y: float, yaw: float, rng: np.random.Generator,
                 spec: LeggedSpec = LeggedSpec()) -> None:
        reach = math.sqrt(max(0.0, (spec.upper_leg + spec.lower_leg) ** 2 - spec.hip_height**2))
        self.max_stride = 2.0 * reach * spec.stride_margin
        top = self.max_stride * spec.max_step_hz / 2.0  # a trot covers one stride per two steps of a pair
        super().__init__(world, x, y, yaw, rng, spec.radius, top, spec.max_accel, spec.max_yaw_rate,
                         spec.max_yaw_accel)
        self.spec = spec
        self.phase = 0.0  # 0..1 over one gait cycle; pair A in stance for phase < 0.5
        self.step_hz = spec.min_step_hz
        self.slip = 0.0
        self.steps = 0
        self.feet = self._nominal_feet()
        # the divisors of ``limits``, fixed by the geometry: worked out once, not on every tick
        self._stride_divisor = max(1e-6, self.max_stride)
        self._speed_divisor = self.max_speed + 1e-6

    def _hips(self) -> list[tuple[float, float]]:
        x, y, a = self.pose
        s = self.spec
        c, sn = math.cos(a), math.sin(a)
        out = []
        for fx, fy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):  # FL, FR, RL, RR
            lx, ly = fx * s.body_half_length, fy * s.body_half_width
            out.append((x + lx * c - ly * sn, y + lx * sn + ly * c))
        return out

    def _nominal_feet(self) -> list[tuple[float, float]]:
        return self._hips()

    def limits(self, speed: float, yaw_rate: float) -> tuple[float, float]:
        """Every physics step calls this: the three ``_clamp`` calls and ``max(0.3, f)`` are written out (the
        same comparisons in the same order, so the same floats), as a helper's call costs more than its
        arithmetic."""
        s = self.spec
        # choose the step frequency for this speed, then clamp speed to what the stride allows at that frequency
        need_hz = 2.0 * abs(speed) / self._stride_divisor
        hi, lo = s.max_step_hz, s.min_step_hz
        need_hz = need_hz if need_hz < hi else hi
        step_hz = self.step_hz = need_hz if need_hz > lo else lo
        cap = self.max_stride * step_hz / 2.0
        speed = speed if speed < cap else cap
        speed = speed if speed > -cap else -cap
        # turning also uses up stride: the outer feet travel further
        free = 1.0 - abs(speed) / self._speed_divisor
        turn_cap = s.max_yaw_rate * (free if free > 0.3 else 0.3)  # ``max(0.3, free)``, NaN alike
        yaw_rate = yaw_rate if yaw_rate < turn_cap else turn_cap
        return speed, (yaw_rate if yaw_rate > -turn_cap else -turn_cap)

    def after_step(self, dt: float) -> None:
        # (``Robot.after_step`` named, not ``super()``: no proxy object built every physics step)
        Robot.after_step(self, dt)
        old = self.phase
        phase = self.phase = (old + self.step_hz * dt) % 1.0
        # ``abs(v) > 0.02`` of the speed and of the rate as two comparisons each (the same test, NaN included)
        speed, rate = self.speed, self.yaw_rate
        moving = speed > 0.02 or speed < -0.02 or rate > 0.02 or rate < -0.02
        if moving and (old < 0.5 <= phase or phase < old):
            # touchdown of a diagonal pair: Raibert foot placement ahead of the hip, plus slip
            self.steps += 1
            self.slip = self.spec.slip_std * self.normal()
            pair = (0, 3) if self.phase < 0.5 else (1, 2)
            hips = self._hips()
            x, y, a = self.pose
            ahead = 0.25 * self.speed / max(self.step_hz, 1e-6)
            for i in pair:
                hx, hy = hips[i]
                self.feet[i] = (hx + ahead * math.cos(a), hy + ahead * math.sin(a))

    def odometry_speed(self, dt: float) -> float:
        # stance-foot kinematics measure the body's motion relative to the feet, wrong by the step's slip; a
        # body held by a wall while the gait goes on slips its stance feet, and the legs still report the gait
        return self.speed * (1.0 + self.slip) + self.spec.leg_odo_noise * self.normal()


# the robot bodies by the vehicle kind that drives them (the plant registry's native vehicles, sim.registry)
ROBOTS: dict[str, type[Robot]] = {cls.kind: cls for cls in (Rover, Legged)}


def make_robot(kind: str, world: World, x: float, y: float, yaw: float, rng: np.random.Generator) -> Robot:
    """The pymunk body of a ``kind`` of robot (every plant drives one: the autopilots a rover)."""
    if kind not in ROBOTS:
        raise ValueError(f"unknown vehicle {kind!r} ({' or '.join(ROBOTS)})")
    return ROBOTS[kind](world, x, y, yaw, rng)
