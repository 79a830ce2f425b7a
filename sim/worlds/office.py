"""Office buildings: rooms off a corridor, the operator outside the entrance, the link lost in a far room.

The building is a double-loaded corridor (rooms on both sides of one straight corridor, the usual office plan)
entered from the yard at its south end. The operator drives in along the corridor, through a room's door and into
the room's far corner; the partitions between the rooms and the outer wall between that corner and the station
take the link away.

Where the figures come from (ranges, not measurements of one building):

- Doors 0.9-3.0 m clear (docs/architecture.md §7.1). The ADA Standards (§404.2.3) ask 32 in (0.81 m) clear at
  least; a 36 in (0.91 m) leaf is the typical office door, double doors and open doorways run to about 3 m. A door
  narrower than the robot's width + 0.3 m cannot be driven through: the validity check redraws a world whose route
  needs one.
- Corridors 1.5-2.4 m clear: building codes (IBC §1020.2) ask 44 in (1.12 m) at least where more than 50 people use
  it; offices typically have 1.5-1.8 m, main corridors more.
- Rooms 3-6 m along the corridor and 3.5-6 m deep: typical cellular offices (a 10 m² single office is about
  3 x 3.5 m; meeting rooms are larger).
- Partitions 3-6 dB at 2.4 GHz: typical published measurements of plasterboard (drywall) on studs put one wall at
  about 3-5 dB (ITU-R P.2040 gives the materials' electrical properties; NIST's building-penetration measurements
  (NISTIR 6055, 1997) report drywall losses of a few dB).
- Outer walls 10-20 dB: brick and concrete walls in the same kinds of measurement run from about 10 dB (brick,
  block) to 20 dB and more (reinforced concrete), depending on thickness and reinforcement: typical figures.
- Path-loss exponent 2.0-2.4 along the line of sight: the walls are counted one by one, so the exponent is near
  free space's; ITU-R P.1238's larger office coefficient (about 3 at 2.4 GHz) already includes the walls.
- The station 15-80 m from the entrance, within 60 degrees of straight out, 0-20 dBm: a handheld radio or a SiK
  telemetry radio (its TXPOWER runs to 20 dBm) in the yard or across the car park. Nearer and louder, a small
  office does not lose the link at all (its few walls add some 15-25 dB); such draws are redrawn.
- GPS denied inside (the whole footprint), as in ``sim/scenarios/building.toml``.
"""

from __future__ import annotations

import math

import numpy as np

from link.radio import RadioParams
from sim.scenario import Scenario
from sim.world import Station
from sim.worlds import build, check

KIND = "office"
SIZES = {"rooms": (2, 20)}  # name -> (lowest, highest): the family's size fields
DOOR_M = (0.9, 3.0)
CORRIDOR_M = (1.5, 2.4)
ROOM_LENGTH_M = (3.0, 6.0)
ROOM_DEPTH_M = (3.5, 6.0)
PARTITION_DB = (3.0, 6.0)
OUTER_DB = (10.0, 20.0)
PARTITION_T, OUTER_T = 0.15, 0.3  # m: wall thicknesses
SPEED = 1.0  # m/s in the corridor and the room
STATION_M = (15.0, 60.0)  # m from the entrance
BEARING_DEG = (45.0, 85.0)  # off the corridor's axis: the operator stands off to one side of the front
POWER_DBM = (0.0, 15.0)


def _u(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(rng.uniform(*lo_hi))


def generate(rng: np.random.Generator, rooms: int) -> Scenario:
    """One office building with ``rooms`` rooms, drawn from ``rng``."""
    cw = _u(rng, CORRIDOR_M)
    n_left = (rooms + 1) // 2
    n_right = rooms - n_left
    left_lengths = [_u(rng, ROOM_LENGTH_M) for _ in range(n_left)]
    length = sum(left_lengths)
    spare = length - 2.5 * max(1, n_right)
    right_lengths = [2.5 + spare * f for f in rng.dirichlet(np.ones(max(1, n_right)))] if n_right else []
    depth = {1: _u(rng, ROOM_DEPTH_M), -1: _u(rng, ROOM_DEPTH_M)}
    outer_db, half = _u(rng, OUTER_DB), cw / 2
    walls, rooms_drawn = [], []
    # the outer walls: the front with the entrance (the corridor's width) open, the sides, the back
    y_left, y_right = half + depth[1], -(half + depth[-1]) if n_right else -half
    walls.append(build.wall([(0.0, half + OUTER_T / 2), (0.0, y_left), (length, y_left), (length, y_right),
                             (0.0, y_right), (0.0, -half - OUTER_T / 2)], OUTER_T, outer_db))
    for side, lengths in ((1, left_lengths), (-1, right_lengths)):
        x, face, doors = 0.0, side * (half + PARTITION_T / 2), []
        for k, room_len in enumerate(lengths):
            door = min(_u(rng, DOOR_M), room_len - 0.8)
            centre = x + float(rng.uniform(0.4 + door / 2, room_len - 0.4 - door / 2))
            doors.append((centre - door / 2 - PARTITION_T / 2, centre + door / 2 + PARTITION_T / 2))
            rooms_drawn.append((side, x, x + room_len, centre, door))
            if k:  # the partition between this room and the one before
                walls.append(build.wall([(x, face), (x, side * (half + depth[side]))], PARTITION_T,
                                        _u(rng, PARTITION_DB)))
            x += room_len
        # the corridor wall on this side, with a door into each room
        edges = [0.0] + [e for d in doors for e in d] + [length]
        db = _u(rng, PARTITION_DB)
        for a, b in zip(edges[0::2], edges[1::2], strict=True):
            if b - a > 0.05:
                walls.append(build.wall([(a, face), (b, face)], PARTITION_T, db))
    yaw = math.radians(float(rng.uniform(*BEARING_DEG)) * (1 if rng.random() < 0.5 else -1))
    dist = float(rng.uniform(*STATION_M))
    station = Station("gcs", build.mm(-dist * math.cos(yaw)), build.mm(dist * math.sin(yaw)), 255,
                      round(float(rng.uniform(*POWER_DBM)), 1))
    # the room: in the back half, on the side away from the station (more walls between)
    away = -1 if station.y > 0 else 1
    choices = [r for r in rooms_drawn if r[0] == away]
    side, x0, x1, door_x, _door = choices[int(rng.integers(len(choices) // 2, len(choices)))]
    inner = side * (half + depth[side] - 1.2)  # 1.2 m short of the outer wall
    far_x = x1 - 1.2 if door_x - x0 < x1 - door_x else x0 + 1.2  # the corner away from the door
    start = (-float(rng.uniform(3.0, 6.0)), 0.0)
    line = [start, (door_x, 0.0), (door_x, side * (half + depth[side] / 2)), (far_x, inner)]
    radio = RadioParams(exponent=round(float(rng.uniform(2.0, 2.4)), 2),
                        shadowing_db=round(float(rng.uniform(2.0, 3.0)), 1),
                        fade_width_db=round(float(rng.uniform(3.0, 6.0)), 1))
    denied = [((0.3, y_right), (length, y_right), (length, y_left), (0.3, y_left))]
    description = (f"A generated office: {rooms} rooms off a {cw:.1f} m corridor {length:.0f} m long; the operator "
                   "drives from the yard into a far room, where partitions and the outer wall take the link away.")
    return build.scenario(KIND, description, walls, denied, station, radio, line, SPEED)


def check_world(sc: Scenario) -> check.Verdict:
    """The validity check of every family (``sim.worlds.check``)."""
    return check.check(sc)
