"""Pose estimation: an extended Kalman filter (filterpy) fusing odometry, a rate gyro and position fixes.

State ``[x, y, yaw, gyro_bias]`` in the local frame (x north, y east, yaw clockwise from north, NED-style).
Odometry (wheel or leg) gives forward speed, the gyro gives yaw rate with a slowly drifting bias, and position fixes
(GNSS, UWB, a total station...) arrive at a few hertz and drop out in denied zones. Through a dropout the filter
dead-reckons and its covariance grows honestly, which is what the trail's crumbs record as their std-dev.

Odometry can lie: wheels spinning against a wall, feet slipping, report motion the body does not make, and dead
reckoning through a denied zone would carry the lie into the trail (and a return would "arrive" while standing
still). Two checks catch it. An inertial speed, integrated from the forward accelerometer and leaning on the
odometry only while the two agree, exposes sustained slip: while it lasts the filter predicts with the inertial speed
and inflates its covariance, and ``slipping`` tells the return that it is making no real progress. And a run of
position fixes all gated out as outliers means the estimate, not the fixes, has gone wrong: the covariance is
inflated by the innovation and the fix is taken, instead of rejecting every fix from then on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter


@dataclass(frozen=True)
class EstimatorConfig:
    speed_noise: float = 0.05  # m/s per sqrt(s): odometry speed error (slip, scale)
    gyro_noise: float = 0.02  # rad/s per sqrt(s)
    bias_walk: float = 0.0005  # rad/s per sqrt(s): gyro bias random walk
    fix_gate: float = 5.0  # Mahalanobis-like gate (sigma): a fix further off is an outlier
    fix_streak: int = 3  # this many outliers in a row: the estimate has diverged, not the fixes
    slip_speed: float = 0.3  # m/s: odometry this far from the inertial speed is slipping
    slip_after: float = 0.5  # s: ... when it lasts this long
    inertial_tau: float = 2.0  # s: the inertial speed leans on agreeing odometry with this time constant
    residual_tau: float = 0.2  # s: smoothing of odometry minus inertial speed (odometry noise is per sample)
    accel_bias_tau: float = 20.0  # s^2: how slowly the accelerometer bias is learnt


class Pose(NamedTuple):
    """One estimator output. A named tuple rather than a frozen dataclass: a new one is made every 20 ms tick,
    and a tuple is built at a third of the cost, with the same names and the same immutability."""

    x: float
    y: float
    yaw: float
    std: float  # 1-sigma horizontal position uncertainty (m)
    t: float


def _h_pos(x: np.ndarray) -> np.ndarray:
    return x[:2]


_H_POS = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])


_I2 = np.eye(2)
_I2.flags.writeable = False


def _jac_pos(_x: np.ndarray) -> np.ndarray:
    return _H_POS


class Estimator:
    """Wraps the filter with time handling and outlier gating. Time is an argument, never read from a clock."""

    def __init__(self, x: float, y: float, yaw: float, t: float, pos_std: float = 0.5, yaw_std: float = 0.05,
                 config: EstimatorConfig | None = None) -> None:
        self.config = config or EstimatorConfig()
        f = ExtendedKalmanFilter(dim_x=4, dim_z=2)
        f.x = np.array([[x], [y], [yaw], [0.0]])
        f.P = np.diag([pos_std**2, pos_std**2, yaw_std**2, 0.01**2])
        f.F = np.eye(4)
        self._f = f
        self.t = t
        self.fixes_used = 0
        self.fixes_rejected = 0
        self._pose: Pose | None = None
        # x (4) then P (16, row by row) as floats while only predictions and headings ran since the last position
        # fix (None: the filter's arrays hold the state): at 50 Hz between fixes, building arrays every tick cost
        # more than the arithmetic
        self._state: tuple[float, ...] | None = None
        self._r_std = math.nan  # the std the cached R was made for (nan: none yet)
        self._r = _I2
        self.inertial_speed = 0.0
        self.accel_bias = 0.0  # m/s^2, learnt while odometry and accelerometer agree
        self.residual = 0.0  # odometry minus inertial speed, smoothed
        self.slip_since: float | None = None  # when the current run of odometry-inertial disagreement began
        self.slip_time = 0.0  # s of slip seen since start, for the record
        self.outlier_streak = 0
        self.divergences = 0  # times a run of rejected fixes showed the estimate had gone wrong

    @property
    def slipping(self) -> bool:
        """The odometry has disagreed with the accelerometer for ``slip_after`` seconds: no real progress."""
        return self.slip_since is not None and self.t - self.slip_since >= self.config.slip_after

    def _check_odometry(self, speed: float, accel: float, dt: float) -> float:
        """Update the inertial speed; returns the odometry speed the filter may trust (the inertial speed while
        slipping) and keeps ``slip_since``."""
        c = self.config
        if abs(speed) < 0.02:
            self.inertial_speed = 0.0  # the wheels or legs stand still: so does the body (a zero-velocity update)
        else:
            self.inertial_speed += (accel - self.accel_bias) * dt
        r = speed - self.inertial_speed
        self.residual += (r - self.residual) * min(1.0, dt / c.residual_tau)
        if abs(self.residual) < c.slip_speed:
            # agreeing: lean on the odometry, and learn the accelerometer's bias from what the leaning corrects
            self.inertial_speed += r * min(1.0, dt / c.inertial_tau)
            self.accel_bias -= r * dt / c.accel_bias_tau
            self.slip_since = None
            return speed
        if self.slip_since is None:
            self.slip_since = self.t
        self.slip_time += dt
        # slipping wheels or feet drive the body slower than they turn, never faster nor the other way: this
        # bounds how far the accelerometer's bias can carry the inertial speed through a long slip
        self.inertial_speed = min(max(self.inertial_speed, min(0.0, speed)), max(0.0, speed))
        return self.inertial_speed

    def predict(self, speed: float, yaw_rate: float, t: float, accel: float | None = None) -> None:
        """Unicycle prediction over ``t - self.t``: x' = f(x, u), P' = F P F' + Q.

        F is the identity plus three terms, so F P F' is written out in scalars; at 50 Hz the generic 4x4 matrix
        path was the largest single cost of the vehicle tick. The filter object and its updates stay filterpy's.
        With ``accel`` (forward, m/s^2) the odometry is checked against it first; while it slips, the inertial
        speed drives the prediction and the speed noise grows by the disagreement, so the crumbs laid meanwhile
        say how little is known instead of recording motion that did not happen.
        """
        dt = t - self.t
        if dt <= 0:
            return
        c = self.config
        qv_extra = 0.0
        if accel is not None:
            trusted = self._check_odometry(speed, accel, dt)
            if trusted != speed:
                qv_extra = (speed - trusted) ** 2 * dt  # as uncertain as the wheels and the IMU disagree
                speed = trusted
        state = self._state  # (``_values()``, its common case written out: this runs every tick)
        (x, y, yaw, b, p00, p01, p02, p03, p10, p11, p12, p13, p20, p21, p22, p23, p30, p31, p32, p33) = (
            state if state is not None else self._values())
        cs, sn = math.cos(yaw), math.sin(yaw)
        a02, a12, a23 = -speed * sn * dt, speed * cs * dt, -dt
        # rows: F P
        r00, r01, r02, r03 = p00 + a02 * p20, p01 + a02 * p21, p02 + a02 * p22, p03 + a02 * p23
        r10, r11, r12, r13 = p10 + a12 * p20, p11 + a12 * p21, p12 + a12 * p22, p13 + a12 * p23
        r20, r21, r22, r23 = p20 + a23 * p30, p21 + a23 * p31, p22 + a23 * p32, p23 + a23 * p33
        qv, qw, qb = (c.speed_noise**2) * dt + qv_extra, (c.gyro_noise**2) * dt, (c.bias_walk**2) * dt
        q0, q1, q2 = qv * cs * cs, qv * cs * sn, qv * sn * sn
        # columns: (F P) F' + Q
        self._state = (
            x + speed * cs * dt, y + speed * sn * dt, yaw + (yaw_rate - b) * dt, b,
            r00 + a02 * r02 + q0, r01 + a12 * r02 + q1, r02 + a23 * r03, r03,
            r10 + a02 * r12 + q1, r11 + a12 * r12 + q2, r12 + a23 * r13, r13,
            r20 + a02 * r22, r21 + a12 * r22, r22 + a23 * r23 + qw, r23,
            p30 + a02 * p32, p31 + a12 * p32, p32 + a23 * p33, p33 + qb,
        )
        self.t = t
        self._pose = None

    def _values(self) -> tuple[float, ...]:
        """x then P as floats: kept from the last prediction, or read from the filter after one of its updates."""
        state = self._state
        if state is None:
            f = self._f
            # (nested lists unpacked in Python: two numpy calls, where slicing and raveling first took four)
            (x0,), (x1,), (x2,), (x3,) = f.x.tolist()
            p0, p1, p2, p3 = f.P.tolist()
            state = self._state = (x0, x1, x2, x3, *p0, *p1, *p2, *p3)
        return state

    def _filter(self) -> ExtendedKalmanFilter:
        """The filter with the state kept in floats written back into its arrays, before filterpy's update reads
        them; afterwards the update's arrays are the state again."""
        f = self._f
        state = self._state
        if state is not None:
            f.x = np.array(state[:4]).reshape(4, 1)
            f.P = np.array(state[4:]).reshape(4, 4)
            f.x_prior, f.P_prior = f.x, f.P
            self._state = None
        return f

    def _noise(self, std: float) -> np.ndarray:
        """R for a fix of this std, made once per std (every fix of a receiver carries the same one)."""
        if std != self._r_std:
            self._r = _I2 * std * std
            self._r_std = std
        return self._r

    def fix(self, x: float, y: float, std: float) -> bool:
        """Fuse a position fix; returns False if it was gated out as an outlier.

        The gate is worked out on the floats, before any array is built: S = P[:2, :2] + std^2 I is 2x2, so
        r' S^-1 r has a closed form, and a rejected fix never touches numpy (the float state stays as it is).
        The closed form rounds differently from the ``np.linalg.solve`` it replaced; only the yes/no of the gate
        depends on it, never a stored value. An accepted fix is handed to filterpy's update, once, as before:
        at a few hertz, cache-cold, every numpy call around it cost more than its arithmetic."""
        s = self._values()
        var = std * std
        r0, r1 = x - s[0], y - s[1]
        s00, s01, s10, s11 = s[4] + var, s[5], s[8], s[9] + var  # S = P[:2, :2] + R
        m2 = (s11 * r0 * r0 - (s01 + s10) * r0 * r1 + s00 * r1 * r1) / (s00 * s11 - s01 * s10)
        if m2 > self.config.fix_gate**2:
            self.outlier_streak += 1
            if self.outlier_streak < self.config.fix_streak:
                self.fixes_rejected += 1
                return False
            # every recent fix disagrees the same way: the dead reckoning drifted (odometry slipped) beyond what
            # the covariance admits. Widen the position covariance to the disagreement (P[:2, :2] + r r') and
            # take the fix.
            self.divergences += 1
            p = list(s[4:])
            p[0], p[1], p[4], p[5] = p[0] + r0 * r0, p[1] + r0 * r1, p[4] + r1 * r0, p[5] + r1 * r1
            self._state = (*s[:4], *p)
        self.outlier_streak = 0
        f = self._filter()
        f.update(np.array(((x,), (y,))), _jac_pos, _h_pos, R=self._noise(std))
        self._pose = None
        self.fixes_used += 1
        return True

    def heading(self, yaw: float, std: float) -> None:
        """Fuse an absolute heading; the innovation is wrapped so that +-pi is one angle.

        H picks the yaw, so the gain K is P's yaw column over S, the state update is four scalar products, and
        I - K H is the identity with its yaw column replaced (every other entry is exactly 0 or 1). The covariance
        update stays the matrix product (I - K H) P, which is what fixes its rounding."""
        s = self._values()
        S = s[14] + std * std  # P[2, 2]
        innov = (yaw - s[2] + math.pi) % (2 * math.pi) - math.pi
        k0, k1, k2, k3 = s[6] / S, s[10] / S, s[14] / S, s[18] / S  # P H' / S
        # (0.0 - k, not -k: the same signed zero as the matrix subtraction when k is zero; one flat tuple reshaped,
        # the same array as four nested rows at two thirds of the cost)
        i_kh = np.array((1.0, 0.0, 0.0 - k0, 0.0,
                         0.0, 1.0, 0.0 - k1, 0.0,
                         0.0, 0.0, 1.0 - k2, 0.0,
                         0.0, 0.0, 0.0 - k3, 1.0)).reshape(4, 4)
        p0, p1, p2, p3 = (i_kh @ np.array(s[4:]).reshape(4, 4)).tolist()  # (rows unpacked: no ravel call)
        self._state = (s[0] + k0 * innov, s[1] + k1 * innov, s[2] + k2 * innov, s[3] + k3 * innov,
                       *p0, *p1, *p2, *p3)
        self._pose = None

    @property
    def pose(self) -> Pose:
        if self._pose is None:
            s = self._state  # (``_values()``, its common case written out: a pose is made every tick)
            if s is None:
                s = self._values()
            x0, x1, x2, p00, p11 = s[0], s[1], s[2], s[4], s[9]
            std = math.sqrt(max(0.0, 0.5 * (p00 + p11)))
            yaw = (x2 + math.pi) % (2 * math.pi) - math.pi
            # (``_make`` from all five fields in order: it skips the keyword handling of the named tuple's generated
            # ``__new__``, a pose being made every tick)
            self._pose = Pose._make((x0, x1, yaw, std, self.t))
        return self._pose

    @property
    def covariance(self) -> np.ndarray:
        return self._filter().P.copy()
