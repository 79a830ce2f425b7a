"""The range data a rover reports over MAVLink, as the vehicle's range sensor (``vehicle.io.Scan``;
docs/architecture.md §11.4).

Why: the native return keeps its body off what its range sensor sees (``vehicle.standoff``) and cuts only corners
the sensor saw free (``vehicle.clearance``); a companion return had no such sense and touched door jambs in
generated offices (issue 41: 3-4 of 10 returns beside ArduPilot). A real rover carries the sensors: ArduPilot
sends one DISTANCE_SENSOR per rangefinder (RNGFNDn_TYPE, RNGFNDn_ORIENT) and per proximity sector, PX4 reports its
distance sensors the same way, and a lidar driver on the vehicle sends OBSTACLE_DISTANCE (72 sectors). Both kinds,
from the autopilot or from any other component of the same system, become beams of one ``Scan``, which the control
loop feeds to the standoff and the free-space grid exactly as the native rover's sweep.

Each message is range-checked where it enters; what does not hold is dropped and counted by reason in ``counts``,
never raised into the tick:
- DISTANCE_SENSOR (distances in cm): an orientation that points the beam off the horizontal (up, down, pitched
  more than HORIZONTAL) or that is not in MAV_SENSOR_ORIENTATION; MAV_SENSOR_ROTATION_CUSTOM without a usable
  quaternion; max_distance 0 or below min_distance; current_distance UINT16_MAX (unknown) or below min_distance;
  signal_quality 1 (the sensor says its reading is invalid). current_distance above max_distance is a beam that
  saw nothing within its reach.
- OBSTACLE_DISTANCE (cm per sector): no usable increment (increment_f, else increment) or angle_offset, a frame
  that is neither the body's (MAV_FRAME_BODY_FRD) nor north-aligned (MAV_FRAME_GLOBAL, LOCAL_NED and kin; those
  need the vehicle's heading), bad limits. Per sector: UINT16_MAX is unknown (skipped, not counted),
  max_distance + 1 and beyond nothing within reach, below min_distance skipped and counted.

A reading is used once, in the scan of the first ``scan`` after it arrived, and not at all if that is more than
``vehicle.standoff.MAX_AGE`` later: its bearing is from the heading of the moment it arrived. Pure in the house
sense: no clock, no socket; time is an argument.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.io import Scan
from vehicle.standoff import MAX_AGE

UINT16_MAX = 65535
HORIZONTAL = math.radians(10.0)  # a beam pitched further than this off the horizontal sees the floor or the sky
CM = 0.01
SECTORS = 72  # OBSTACLE_DISTANCE's distances
QUIET_S = 5.0  # s after the companion's start without any range data before it says the return keeps no standoff
BODY_FRAMES = frozenset((apm.MAV_FRAME_BODY_FRD, apm.MAV_FRAME_BODY_OFFSET_NED))  # sectors from the vehicle's front
NORTH_FRAMES = frozenset((apm.MAV_FRAME_GLOBAL, apm.MAV_FRAME_LOCAL_NED, apm.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                          apm.MAV_FRAME_GLOBAL_INT, apm.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                          apm.MAV_FRAME_LOCAL_OFFSET_NED, apm.MAV_FRAME_BODY_NED, apm.MAV_FRAME_GLOBAL_TERRAIN_ALT,
                          apm.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT))  # sectors from north
KINDS = ("DISTANCE_SENSOR", "OBSTACLE_DISTANCE")


class Beam(NamedTuple):
    """One reading: its bearing from the heading (rad, clockwise), its range (m; inf: nothing within ``reach``)."""

    bearing: float
    range: float
    reach: float


def _rotations() -> dict[int, tuple[float, float]]:
    """MAV_SENSOR_ORIENTATION -> (bearing of the sensor's beam from the heading, cos of its pitch) for every
    named rotation whose beam lies within HORIZONTAL of the horizontal. A rotation ROLL_r_PITCH_p_YAW_y turns the
    body's x axis (the beam of an unrotated sensor) by yaw(y) * pitch(p) * roll(r), as ArduPilot's rotations do:
    the roll never moves the beam, a pitch of 180 turns it backwards."""
    out: dict[int, tuple[float, float]] = {}
    for value, entry in apm.enums["MAV_SENSOR_ORIENTATION"].items():
        name = entry.name.removeprefix("MAV_SENSOR_ROTATION_")
        if name == "NONE":
            out[value] = (0.0, 1.0)
            continue
        words = name.split("_")
        if len(words) % 2 or not all(w in ("ROLL", "PITCH", "YAW") for w in words[::2]) \
                or not all(w.isdigit() for w in words[1::2]):
            continue  # CUSTOM (the quaternion says), the enum's end marker
        angle = {k: math.radians(float(v)) for k, v in zip(words[::2], words[1::2], strict=True)}
        p, y = angle.get("PITCH", 0.0), angle.get("YAW", 0.0)
        if abs(math.sin(p)) > math.sin(HORIZONTAL):
            continue
        fx, fy = math.cos(p) * math.cos(y), math.cos(p) * math.sin(y)
        out[value] = (math.atan2(fy, fx), math.hypot(fx, fy))
    return out


ROTATIONS = _rotations()


def _custom(q) -> tuple[float, float] | str:
    """(bearing, cos pitch) of the beam a DISTANCE_SENSOR quaternion (w, x, y, z: body -> sensor) points, or why
    not: the body's x axis rotated by it."""
    try:
        w, x, y, z = (float(v) for v in q)
    except (TypeError, ValueError):
        return "bad quaternion"
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not math.isfinite(n) or n < 1e-6:
        return "bad quaternion"  # (all zeros: the sender's "invalid")
    w, x, y, z = w / n, x / n, y / n, z / n
    fx, fy, fz = 1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)
    if abs(fz) > math.sin(HORIZONTAL):
        return "not horizontal"
    return math.atan2(fy, fx), math.hypot(fx, fy)


def distance_beam(m) -> Beam | str:
    """A DISTANCE_SENSOR as a beam, or the reason it is dropped (see the module docstring)."""
    try:
        orientation = int(m.orientation)
        low, high, now = int(m.min_distance), int(m.max_distance), int(m.current_distance)
        quality = int(getattr(m, "signal_quality", 0) or 0)
    except (TypeError, ValueError, AttributeError):
        return "bad field"
    if orientation == apm.MAV_SENSOR_ROTATION_CUSTOM:
        aim = _custom(getattr(m, "quaternion", None))
        if isinstance(aim, str):
            return aim
    elif orientation in ROTATIONS:
        aim = ROTATIONS[orientation]
    elif orientation in apm.enums["MAV_SENSOR_ORIENTATION"]:
        return "not horizontal"
    else:
        return "unknown orientation"
    if high <= 0 or low < 0 or low > high or high >= UINT16_MAX:
        return "bad limits"
    if now >= UINT16_MAX or now < 0:
        return "unknown distance"
    if quality == 1:
        return "invalid signal"
    if now < low:
        return "below minimum"
    bearing, flat = aim
    reach = high * CM * flat
    return Beam(bearing, math.inf if now > high else now * CM * flat, reach)


def obstacle_beams(m, yaw: float | None) -> list[Beam] | str:
    """An OBSTACLE_DISTANCE's sectors as beams (unknown ones left out), or the reason the message is dropped.
    ``yaw``: the vehicle's heading (rad from north, clockwise) when it arrived, for north-aligned frames."""
    try:
        inc_f = float(getattr(m, "increment_f", 0.0) or 0.0)
        inc = inc_f if inc_f > 0.0 else float(int(m.increment))
        offset = float(getattr(m, "angle_offset", 0.0) or 0.0)
        frame = int(getattr(m, "frame", apm.MAV_FRAME_GLOBAL))
        low, high = int(m.min_distance), int(m.max_distance)
        distances = np.asarray(m.distances, dtype=float)
    except (TypeError, ValueError, AttributeError):
        return "bad field"
    if not (math.isfinite(inc) and 0.0 < inc <= 360.0):
        return "bad increment"
    if not math.isfinite(offset):
        return "bad angle"
    if frame in BODY_FRAMES:
        turn = 0.0
    elif frame in NORTH_FRAMES:
        if yaw is None or not math.isfinite(yaw):
            return "no heading"
        turn = -yaw
    else:
        return "unknown frame"
    if high <= 0 or low < 0 or low > high or high >= UINT16_MAX or distances.shape != (SECTORS,):
        return "bad limits"
    n = min(SECTORS, math.ceil(360.0 / inc - 1e-9))
    d = distances[:n]
    i = np.flatnonzero((d != UINT16_MAX) & (d >= low))
    bearings = np.remainder(np.radians(offset + i * inc) + turn + math.pi, 2.0 * math.pi) - math.pi
    ranges = np.where(d[i] > high, math.inf, d[i] * CM)
    reach = high * CM
    return [Beam(float(b), float(r), reach) for b, r in zip(bearings, ranges, strict=True)]


class RangeSensors:
    """The range data heard from the vehicle's components (``heard``), given to the vehicle as scans (``scan``).
    Mutable: the readings wait here between the message that brought them and the tick that reads them."""

    def __init__(self) -> None:
        self.waiting: list[tuple[float, Beam]] = []  # (arrival, beam) not yet in a scan
        self.counts: dict[str, int] = {}  # "messages" (and per kind), "beams", "stale", each reason one was dropped
        self.sources: set[tuple[int, int, str]] = set()  # (sysid, compid, message) that gave usable readings
        self.first_heard: float | None = None

    def _count(self, what: str, n: int = 1) -> None:
        self.counts[what] = self.counts.get(what, 0) + n

    def heard(self, m, t: float, yaw: float | None) -> None:
        """One DISTANCE_SENSOR or OBSTACLE_DISTANCE at ``t``; ``yaw`` the vehicle's heading then (None: unknown)."""
        kind = m.get_type()
        got = distance_beam(m) if kind == "DISTANCE_SENSOR" else obstacle_beams(m, yaw)
        if isinstance(got, str):
            self._count(got)
            return
        beams = [got] if isinstance(got, Beam) else got
        self._count("messages")
        self._count(kind)
        self._count("beams", len(beams))
        self.sources.add((m.get_srcSystem(), m.get_srcComponent(), kind))
        if self.first_heard is None:
            self.first_heard = t
        self.waiting.extend((t, b) for b in beams)

    def scan(self, t: float) -> Scan | None:
        """The beams that arrived since the last scan and no more than MAX_AGE before ``t``, as one scan (None:
        none). Its reach is the longest beam's; a beam that saw nothing within a shorter reach of its own is left
        out (it says nothing of the space between its reach and the scan's)."""
        if not self.waiting:
            return None
        fresh = [b for at, b in self.waiting if 0.0 <= t - at <= MAX_AGE]
        stale = len(self.waiting) - len(fresh)
        if stale:
            self._count("stale", stale)
        self.waiting = []
        if not fresh:
            return None
        reach = max(b.reach for b in fresh)
        kept = [b for b in fresh if math.isfinite(b.range) or b.reach >= reach]
        return Scan(np.array([b.bearing for b in kept]), np.array([b.range for b in kept]), reach)

    def describe(self) -> str:
        """The sources heard, for the companion's notice: e.g. "DISTANCE_SENSOR from 1/1"."""
        return ", ".join(f"{kind} from {s}/{c}" for s, c, kind in sorted(self.sources)) or "none"
