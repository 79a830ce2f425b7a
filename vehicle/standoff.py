"""Keeping the robot's body off what its range sensor sees now, whatever the estimate says.

Why: a return's route is kept clear in the estimated frame (``vehicle.clearance``), where each wall was booked with
the estimate of the moment it was seen. After a stretch without fixes the estimate is 0.1-0.2 m off the truth, and
in a 1.2 m culvert that is all the slack a 0.7 m rover has: returns came within a few mm of a wall, and some touched.
A sweep of the range sensor is measured from the body, so what it says about the next metre holds whatever the
estimate's error; with the check no return touched (the generated culverts' runs with and without it are in
docs/evidence.md, "The measurements behind the vehicle's code").

Each tick of a return the follower's command is checked against the returns of the latest sweep, carried into the
body frame of now by the estimate's own motion since the sweep (half a second of dead reckoning: a few mm, where the
estimate's absolute error is the 0.1-0.2 m above). The arc the command would drive over the next HORIZON seconds
must keep the body STANDOFF clear of every return, or at least not bring it closer than it is; if it does not, the
yaw rate nearest the follower's that does is taken, at the follower's speed or, failing that, at less (a dynamic
window over a few arcs, as Fox, Burgard and Thrun's 1997 local planner checks them). Where no arc keeps STANDOFF (a
door barely wider than the robot) an arc that touches nothing is driven at the slowest pace, so a return is never
stalled by its own margin; where none touches nothing, the robot stops and may turn. A robot that never gets near a
wall drives exactly the follower's command, and a robot without the sensor, or with RTL_BODY_R 0, always does.

A sweep of a handful of beams (fewer than SPARSE: a rover's rangefinders, which a companion hears as DISTANCE_SENSOR,
``vehicle.companion.ranges``) sees a wall only where a beam points. Its returns are kept with those of the sweeps
before it for MEMORY s (``remember``), each where it was seen in the estimated frame, so the door jamb the 45-degree
beam saw a moment ago still counts as the body passes it. A full sweep says all there is and replaces the last.

Pure: functions of the sweep, the poses and the command; the control loop keeps the sweep between ticks.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from vehicle.io import Scan

STANDOFF = 0.05  # m kept between the body and a return: the sensor's own noise (2 cm a beam) and the tick's slack
HORIZON = 0.8  # s of the command's arc checked: what the follower can change before it gets there
SAMPLES = 8  # points along the arc
NEAR = 2.0  # m: returns further than this from the robot when swept are not kept (no arc of HORIZON reaches them)
MAX_AGE = 1.5  # s: a sweep older than this (three at the simulated 2 Hz: the sensor has stopped) says nothing of now
TURNS = np.array([0.0, 0.15, -0.15, 0.3, -0.3, 0.5, -0.5, 0.75, -0.75, 1.0, -1.0])  # rad/s tried around the follower's
PACES = (1.0, 0.5, 0.25)  # fractions of the follower's speed tried, in order
SPARSE = 24  # beams: a sweep of fewer is a handful of rangefinders, remembered (``remember``); a lidar has more
MEMORY = 1.0  # s a sparse sweep's returns are kept: about a metre of driving, in which the estimate moves by mm


class Sweep(NamedTuple):
    """The returns of one sweep within NEAR, as points in the estimated frame of the moment ``t`` it was taken
    (``born``: each point's own time, where sweeps of a few beams are kept together; None: all at ``t``)."""

    x: np.ndarray
    y: np.ndarray
    t: float
    born: np.ndarray | None = None


def sweep(t: float, x: float, y: float, yaw: float, scan: Scan) -> Sweep | None:
    """The returns of ``scan`` taken at ``t`` at the estimated pose (x, y, yaw) within NEAR; None when the scan is
    not numbers (a driver's scan is input: dropped here, never raised into the tick)."""
    try:
        b = np.asarray(scan.bearings, dtype=float)
        r = np.asarray(scan.ranges, dtype=float)
        reach = float(scan.max_range)
    except (TypeError, ValueError):
        return None
    if b.shape != r.shape or b.ndim != 1 or not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
        return None
    hit = np.isfinite(b) & np.isfinite(r) & (r >= 0.0) & (r < min(reach, NEAR))
    a = yaw + b[hit]
    return Sweep(x + r[hit] * np.cos(a), y + r[hit] * np.sin(a), t)


def remember(kept: Sweep | None, new: Sweep | None, beams: int) -> Sweep | None:
    """The sweep a return keeps off after ``new``, a sweep of ``beams`` beams: ``new`` itself if it is a full one
    (SPARSE beams or more) or none, else ``new`` with the points of ``kept`` that are at most MEMORY older."""
    if new is None or beams >= SPARSE:
        return new
    if kept is None or len(kept.x) == 0:
        return new._replace(born=np.full(len(new.x), new.t))
    born = kept.born if kept.born is not None else np.full(len(kept.x), kept.t)
    young = (new.t - born <= MEMORY) & (born <= new.t)
    return Sweep(np.concatenate([kept.x[young], new.x]), np.concatenate([kept.y[young], new.y]), new.t,
                 np.concatenate([born[young], np.full(len(new.x), new.t)]))


def _arcs(speed: float, turns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame positions (forward, right) along each arc of (speed, turn) at SAMPLES times up to HORIZON."""
    t = np.arange(1, SAMPLES + 1) * (HORIZON / SAMPLES)
    w = turns[:, None]
    wt = w * t[None, :]
    small = np.abs(w) < 1e-6
    safe = np.where(small, 1.0, w)
    fwd = np.where(small, speed * t[None, :], speed / safe * np.sin(wt))
    right = np.where(small, 0.0, speed / safe * (1.0 - np.cos(wt)))
    return fwd, right


def keep_off(seen: Sweep | None, t: float, x: float, y: float, yaw: float, speed: float, yaw_rate: float,
             body: float, max_yaw_rate: float) -> tuple[float, float]:
    """The command (speed, yaw rate) that keeps a body of radius ``body`` STANDOFF off the returns ``seen``, at
    ``t`` from the estimated pose (x, y, yaw): the follower's own if its arc does, else the nearest turn (within
    ``max_yaw_rate``) at the highest pace that does, else the slowest pace on an arc that touches nothing, else a
    stop. An arc passes if it keeps STANDOFF, or if it comes no closer than the body is now (a robot already within
    STANDOFF may still drive away, or along). ``body`` 0, no sweep or one older than MAX_AGE: unchanged."""
    if seen is None or body <= 0.0 or len(seen.x) == 0 or speed == 0.0 or not (0.0 <= t - seen.t <= MAX_AGE):
        return speed, yaw_rate
    dx, dy = seen.x - x, seen.y - y
    c, s = math.cos(yaw), math.sin(yaw)
    fwd, right = dx * c + dy * s, -dx * s + dy * c  # each return in the body frame of now
    dist = np.hypot(fwd, right)
    now = float(dist.min()) - body
    close = dist <= abs(speed) * HORIZON + body + STANDOFF
    if not close.any():
        return speed, yaw_rate
    fwd, right = fwd[close], right[close]
    turns = np.clip(yaw_rate + TURNS, -max_yaw_rate, max_yaw_rate)
    clear: dict[float, np.ndarray] = {}  # per pace, each turn's least clearance along its arc (worked out once)
    # STANDOFF where an arc keeps it; where none does (a door barely wider than the robot), any arc that touches
    # nothing, at the slowest pace; else a stop
    for need, paces in ((min(STANDOFF, now), PACES), (min(0.0, now), PACES[-1:])):
        for pace in paces:
            if pace not in clear:
                af, ar = _arcs(speed * pace, turns)  # (turn, sample)
                d = np.hypot(fwd[None, None, :] - af[:, :, None], right[None, None, :] - ar[:, :, None])
                clear[pace] = d.min(axis=2).min(axis=1) - body
            ok = clear[pace] >= need - 1e-9
            if ok.any():
                i = int(np.flatnonzero(ok)[0])  # TURNS is ordered by how far it leaves the follower's turn
                return speed * pace, float(turns[i])
    return 0.0, yaw_rate
