"""The estimator's odometry checks: wheels spinning against a wall and a diverged estimate do not poison the trail."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from sim.robots import make_robot
from sim.sensors import Sensors
from sim.world import Wall, World
from vehicle.estimator import Estimator

DT = 0.02
EVERYWHERE = ((-100.0, -100.0), (100.0, -100.0), (100.0, 100.0), (-100.0, 100.0))


def _press_into_a_wall(kind: str, seconds: float, use_accel: bool = True):
    """Drive straight at a wall 3 m ahead, with no position fixes at all, and keep pushing."""
    world = World((Wall(((4.0, -5.0), (4.0, 5.0)), 0.5, 30.0),), denied=(EVERYWHERE,))
    rng = np.random.default_rng(2)
    robot = make_robot(kind, world, 0.0, 0.0, 0.0, rng)
    sensors = Sensors(robot, world, rng)
    est = Estimator(0.0, 0.0, 0.0, 0.0, pos_std=0.1, yaw_std=0.02)
    t, std_at_contact, slipping = 0.0, None, []
    for _ in range(int(seconds / DT)):
        robot.command(0.8, 0.0)
        robot.before_step(DT)
        world.step(DT)
        robot.after_step(DT)
        t = round(t + DT, 9)
        r = sensors.read(t, DT)
        est.predict(r.speed, r.yaw_rate, t, r.accel if use_accel else None)
        if r.heading is not None:
            est.heading(r.heading, r.heading_std)
        if world.collisions and std_at_contact is None:
            std_at_contact = est.pose.std
        slipping.append(est.slipping)
    return robot, est, std_at_contact, slipping


@pytest.mark.parametrize("kind", ["rover", "legged"])
def test_the_simulator_spins_wheels_and_slips_feet_against_a_wall(kind):
    robot, est, _, _ = _press_into_a_wall(kind, 12.0, use_accel=False)
    x, _, _ = robot.pose
    assert robot.true_speed == pytest.approx(0.0, abs=0.02)  # the body is held by the rock
    assert x < 4.0 - 0.25 - 0.3
    # the odometry kept reporting the commanded motion: dead reckoning alone believes it went on
    assert est.pose.x > x + 3.0


@pytest.mark.parametrize("kind", ["rover", "legged"])
def test_spinning_odometry_inflates_the_uncertainty_instead_of_moving_the_estimate(kind):
    robot, est, std_at_contact, slipping = _press_into_a_wall(kind, 12.0)
    x, y, _ = robot.pose
    err = math.hypot(est.pose.x - x, est.pose.y - y)
    assert err < 1.0 and err < 2.0 * est.pose.std  # about where it is, and it knows how well
    assert est.slipping and sum(slipping) * DT > 5.0
    assert not any(slipping[:int(2.0 / DT)])  # free driving and accelerating is not slip
    assert std_at_contact is not None and est.pose.std > std_at_contact + 0.3


def test_a_run_of_rejected_fixes_means_the_estimate_diverged_and_it_recovers():
    est = Estimator(0.0, 0.0, 0.0, 0.0, pos_std=0.1)
    t = 0.0
    used = []
    for _ in range(10):  # the robot truly stands 6 m north of where the estimate believes
        t += 0.2
        est.predict(0.0, 0.0, t)
        used.append(est.fix(6.0, 0.0, 0.5))
    assert used[:2] == [False, False]  # one or two far fixes are outliers
    assert est.divergences == 1 and all(used[2:])  # a third in a row: it is the estimate that is wrong
    assert est.pose.x == pytest.approx(6.0, abs=0.5)


def test_a_single_outlier_is_still_rejected():
    est = Estimator(0.0, 0.0, 0.0, 0.0, pos_std=0.1)
    fates = []
    for k, x in enumerate([0.1, 0.0, 8.0, -0.1, 0.0, 9.0, 0.1]):
        est.predict(0.0, 0.0, 0.2 * (k + 1))
        fates.append(est.fix(x, 0.0, 0.5))
    assert fates == [True, True, False, True, True, False, True]
    assert est.divergences == 0 and abs(est.pose.x) < 0.3


def test_heading_is_the_matrix_update_bit_for_bit():
    """The scalar heading update gives exactly what the matrix form K = P H'/S, x + K y, (I - K H) P gives,
    zero entries of the yaw column included (where a signed zero could differ)."""
    H = np.array([[0.0, 0.0, 1.0, 0.0]])
    rng = np.random.default_rng(7)
    for k in range(300):
        A = rng.normal(size=(4, 4)) * 10 ** rng.uniform(-4, 1)
        P = A @ A.T
        if k % 3 == 0:
            P[0, 2] = P[2, 0] = P[3, 2] = P[2, 3] = 0.0  # a yaw uncorrelated with x and the bias, as at start
        x = rng.normal(size=(4, 1))
        yaw, std = rng.uniform(-4, 4), rng.uniform(0.01, 0.5)
        est = Estimator(0.0, 0.0, 0.0, 0.0)
        est._f.x, est._f.P = x.copy(), P.copy()
        est.heading(yaw, std)
        S = float(P[2, 2]) + std * std
        innov = (yaw - float(x[2, 0]) + math.pi) % (2 * math.pi) - math.pi
        K = P @ H.T / S
        want = (*(x + K * innov)[:, 0].tolist(), *((np.eye(4) - K @ H) @ P).ravel().tolist())
        got = est._values()
        assert [struct.pack("<d", v) for v in got] == [struct.pack("<d", v) for v in want]


class _MatrixGateEstimator(Estimator):
    """The position fix as it was written before the float gate: S, r and the gate in numpy, R made per fix."""

    def fix(self, x: float, y: float, std: float) -> bool:
        f = self._filter()
        z = np.array([[x], [y]])
        S = f.P[:2, :2] + np.eye(2) * std * std
        r = z - f.x[:2]
        m2 = float((r.T @ np.linalg.solve(S, r))[0, 0])
        if m2 > self.config.fix_gate**2:
            self.outlier_streak += 1
            if self.outlier_streak < self.config.fix_streak:
                self.fixes_rejected += 1
                return False
            self.divergences += 1
            f.P[:2, :2] = f.P[:2, :2] + r @ r.T
        self.outlier_streak = 0
        f.update(z, lambda _x: np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]]), lambda s: s[:2], R=np.eye(2) * std * std)
        self._pose = None
        self.fixes_used += 1
        return True


def test_the_float_gate_and_cached_noise_take_the_same_fixes_as_the_matrix_gate_bit_for_bit():
    """Fixes near and far (outliers, runs of them that widen the covariance), fix std changing now and then, with
    predictions and headings between: the same verdicts, counters and state, to the last bit."""
    rng = np.random.default_rng(11)
    fast, ref = (cls(0.0, 0.0, 0.3, 0.0, pos_std=0.2) for cls in (Estimator, _MatrixGateEstimator))
    std, t, verdicts = 0.5, 0.0, []
    for k in range(3000):
        t = round(t + DT, 9)
        speed, rate, accel = rng.uniform(-1, 2), rng.normal(0, 0.3), rng.normal(0, 0.5)
        for est in (fast, ref):
            est.predict(speed, rate, t, accel)
        if k % 5 == 0:
            yaw = rng.uniform(-4, 4)
            for est in (fast, ref):
                est.heading(yaw, 0.05)
        if k % 7 == 0:
            if rng.uniform() < 0.05:
                std = float(rng.uniform(0.1, 2.0))
            far = rng.uniform() < 0.5
            p = ref.pose
            fx, fy = p.x + rng.normal(0, 8.0 if far else 0.3), p.y + rng.normal(0, 8.0 if far else 0.3)
            got, want = fast.fix(fx, fy, std), ref.fix(fx, fy, std)
            assert got == want
            verdicts.append(got)
        assert [struct.pack("<d", v) for v in fast._values()] == [struct.pack("<d", v) for v in ref._values()]
    assert (fast.fixes_used, fast.fixes_rejected, fast.divergences) == (
        ref.fixes_used, ref.fixes_rejected, ref.divergences)
    assert ref.divergences > 5 and ref.fixes_rejected > 20 and ref.fixes_used > 100  # every path was taken
    assert np.array_equal(fast.covariance, ref.covariance)
