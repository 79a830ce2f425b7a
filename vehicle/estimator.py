"""Pose estimation: an extended Kalman filter (filterpy) fusing odometry, a rate gyro and position fixes.

State ``[x, y, yaw, gyro_bias]`` in the local frame (x north, y east, yaw clockwise from north, NED-style).
Odometry (wheel or leg) gives forward speed, the gyro gives yaw rate with a slowly drifting bias, and position fixes
(GNSS, UWB, a total station...) arrive at a few hertz and drop out in denied zones. Through a dropout the filter
dead-reckons and its covariance grows honestly, which is what the trail's crumbs record as their std-dev.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter


@dataclass(frozen=True)
class EstimatorConfig:
    speed_noise: float = 0.05  # m/s per sqrt(s): odometry speed error (slip, scale)
    gyro_noise: float = 0.02  # rad/s per sqrt(s)
    bias_walk: float = 0.0005  # rad/s per sqrt(s): gyro bias random walk
    fix_gate: float = 5.0  # Mahalanobis-like gate (sigma): a fix further off is an outlier


@dataclass(frozen=True)
class Pose:
    x: float
    y: float
    yaw: float
    std: float  # 1-sigma horizontal position uncertainty (m)
    t: float


class _EKF(ExtendedKalmanFilter):
    """filterpy's EKF with the unicycle motion model as its (nonlinear) prediction."""

    def predict_x(self, u: np.ndarray = 0) -> None:  # type: ignore[override]
        v, w, dt = float(u[0]), float(u[1]), float(u[2])
        x, y, yaw, b = self.x[:, 0]
        c, s = math.cos(yaw), math.sin(yaw)
        self.x = np.array([[x + v * c * dt], [y + v * s * dt], [yaw + (w - b) * dt], [b]])
        F = self.F
        F[0, 2] = -v * s * dt
        F[1, 2] = v * c * dt
        F[2, 3] = -dt


def _h_pos(x: np.ndarray) -> np.ndarray:
    return x[:2]


_H_POS = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])


_H_YAW = np.array([[0.0, 0, 1.0, 0]])


def _jac_pos(_x: np.ndarray) -> np.ndarray:
    return _H_POS


class Estimator:
    """Wraps the filter with time handling and outlier gating. Time is an argument, never read from a clock."""

    def __init__(self, x: float, y: float, yaw: float, t: float, pos_std: float = 0.5, yaw_std: float = 0.05,
                 config: EstimatorConfig | None = None) -> None:
        self.config = config or EstimatorConfig()
        f = _EKF(dim_x=4, dim_z=2)
        f.x = np.array([[x], [y], [yaw], [0.0]])
        f.P = np.diag([pos_std**2, pos_std**2, yaw_std**2, 0.01**2])
        f.F = np.eye(4)
        self._f = f
        self.t = t
        self.fixes_used = 0
        self.fixes_rejected = 0
        self._F = np.eye(4)
        self._Q = np.zeros((4, 4))
        self._pose: Pose | None = None

    def predict(self, speed: float, yaw_rate: float, t: float) -> None:
        """Unicycle prediction over ``t - self.t``: the filter's own model (``_EKF.predict_x``) for the state, and
        P = F P F' + Q written out for 4x4, because at 50 Hz the generic matrix path dominated the tick."""
        dt = t - self.t
        if dt <= 0:
            return
        c = self.config
        f = self._f
        F = self._F
        F[0, 2] = F[1, 2] = F[2, 3] = 0.0
        f.F = F
        yaw = float(f.x[2, 0])
        qv, qw, qb = (c.speed_noise**2) * dt, (c.gyro_noise**2) * dt, (c.bias_walk**2) * dt
        cs, sn = math.cos(yaw), math.sin(yaw)
        Q = self._Q
        Q[0, 0], Q[0, 1], Q[1, 0], Q[1, 1] = qv * cs * cs, qv * cs * sn, qv * cs * sn, qv * sn * sn
        Q[2, 2], Q[3, 3] = qw, qb
        f.predict_x(np.array((speed, yaw_rate, dt)))
        f.P = F @ f.P @ F.T + Q
        f.x_prior, f.P_prior = f.x, f.P
        self.t = t
        self._pose = None

    def fix(self, x: float, y: float, std: float) -> bool:
        """Fuse a position fix; returns False if it was gated out as an outlier."""
        f = self._f
        z = np.array([[x], [y]])
        S = f.P[:2, :2] + np.eye(2) * std * std
        r = z - f.x[:2]
        m2 = float((r.T @ np.linalg.solve(S, r))[0, 0])
        if m2 > self.config.fix_gate**2:
            self.fixes_rejected += 1
            return False
        f.update(z, _jac_pos, _h_pos, R=np.eye(2) * std * std)
        self._pose = None
        self.fixes_used += 1
        return True

    def heading(self, yaw: float, std: float) -> None:
        """Fuse an absolute heading; the innovation is wrapped so that +-pi is one angle."""
        f = self._f
        H = _H_YAW
        S = float(f.P[2, 2]) + std * std
        innov = (yaw - float(f.x[2, 0]) + math.pi) % (2 * math.pi) - math.pi
        K = f.P @ H.T / S
        f.x = f.x + K * innov
        f.P = (np.eye(4) - K @ H) @ f.P
        self._pose = None

    @property
    def pose(self) -> Pose:
        if self._pose is None:
            x = self._f.x[:, 0]
            P = self._f.P
            std = math.sqrt(max(0.0, 0.5 * (P[0, 0] + P[1, 1])))
            yaw = (x[2] + math.pi) % (2 * math.pi) - math.pi
            self._pose = Pose(float(x[0]), float(x[1]), float(yaw), std, self.t)
        return self._pose

    @property
    def covariance(self) -> np.ndarray:
        return self._f.P.copy()
