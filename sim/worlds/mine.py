"""Mines: an adit driven into a hillside, its drifts bending, dead-end crosscuts off them, rock all round.

The operator stands outside the portal, off to one side, and drives in along the drifts; the link dies where the
rock of the hillside or of a bend stands between the robot and the station (``sim/scenarios/tunnel.toml`` is the
hand-drawn one).

Where the figures come from (typical ranges):

- Drifts 3-5 m wide (docs/architecture.md §7.1): typical development headings and room-and-pillar entries are
  about 3-6 m wide, sized for the loaders and trucks that drive them; 5 m is common in coal room-and-pillar,
  narrower in hard-rock development.
- Bends of 30-90 degrees between straight drifts 10-25 m long, and crosscuts at right angles 6-12 m deep: the
  geometry of room-and-pillar panels (crosscuts square to the entries) and of development drives that turn to
  follow a vein.
- Rock 30-60 dB a wall: solid rock stops 2.4 GHz almost entirely; a path through a pillar or a hillside loses far
  more than any building wall (``tunnel.toml`` takes 60 dB). 30 dB is the floor DESIGN asks.
- A lower path-loss exponent along straight drifts: a straight tunnel guides radio waves, and measured exponents
  there are typically below free space's 2 (values around 1.5-1.9 are commonly reported at 2.4 GHz). The radio
  model (``link.radio``) has one exponent for the whole scenario, not one per region, so a mine world sets its
  scenario's exponent to 1.6-2.0: right along the drifts, too optimistic through the rock, where the walls' own
  30-60 dB each dominate anyway. An approximation, said as one.
- The station 10-40 m from the portal, up to 4 m beyond the drift's side to either side of its axis (on the
  axis it sees down the first drift; off it, the hillside cuts the link sooner), 10-20 dBm (a SiK radio's range
  of power; DARPA SubT's virtual radio transmits 20 dBm); shadowing 2-4 dB.
- GPS denied underground, everywhere past the portal.
"""

from __future__ import annotations

import math

import numpy as np

from link.radio import RadioParams
from sim.scenario import Scenario
from sim.world import Station
from sim.worlds import build, check
from sim.worlds import geometry as geo

KIND = "mine"
SIZES = {"drifts": (1, 8)}
WIDTH_M = (3.0, 5.0)
LEG_M = (10.0, 25.0)
BEND_DEG = (30.0, 90.0)
CROSSCUT_M = (6.0, 12.0)
ROCK_DB = (30.0, 60.0)
ROCK_T = 1.0  # m: a wall's thickness (the rock face of the drift)
FACE_HALF_M = 40.0  # m of hillside either side of the portal
SPEED = 1.2


def _crosscuts(rng: np.random.Generator, line: list[geo.Point], width: float) -> list[tuple[int, float, int, float]]:
    """Dead-end crosscuts: (leg, distance along it, side +1 left / -1 right, depth), each square to its drift, away
    from bends and from every other drift."""
    cuts, placed = [], []
    for leg, (a, b) in enumerate(zip(line[:-1], line[1:], strict=True)):
        span = math.dist(a, b)
        if rng.random() < 0.5 or span < 2 * width + 6:
            continue
        s, side, depth = float(rng.uniform(width + 3, span - width - 3)), int(rng.choice((-1, 1))), \
            float(rng.uniform(*CROSSCUT_M))
        u = geo.unit(a, b)
        root = geo.add(a, u, s)
        tip = geo.add(root, geo.left(u), side * (width / 2 + depth))
        others = [seg for k, seg in enumerate(zip(line[:-1], line[1:], strict=True)) if k != leg] + \
            [seg for _leg, seg in placed]
        clear = min((geo.segment_distance(root, tip, *seg) for seg in others), default=math.inf)
        if clear > width + 2 * ROCK_T + 2 and tip[0] > width:
            cuts.append((leg, s, side, depth))
            placed.append((leg, (root, tip)))
    return cuts


def _side_walls(line: list[geo.Point], width: float, side: int, cuts, db: float) -> list:
    """The drift wall on one side, broken by the crosscuts on that side, and each crosscut's own walls."""
    d = width / 2 + ROCK_T / 2
    off = geo.offset(line, side * d)
    walls, run = [], [off[0]]
    for leg in range(len(line) - 1):
        u = geo.unit(line[leg], line[leg + 1])
        n = geo.left(u)
        for c_leg, s, c_side, depth in sorted(cuts, key=lambda c: c[1]):
            if c_leg != leg or c_side != side:
                continue
            g1 = geo.add(geo.add(line[leg], u, s - d), n, side * d)
            g2 = geo.add(geo.add(line[leg], u, s + d), n, side * d)
            t1, t2 = geo.add(g1, n, side * depth), geo.add(g2, n, side * depth)
            walls.append(build.wall([*run, g1, t1, t2, g2], ROCK_T, db))
            run = [g2]
        run.append(off[leg + 1])
    walls.append(build.wall(run, ROCK_T, db))
    return walls


def generate(rng: np.random.Generator, drifts: int) -> Scenario:
    """One mine of ``drifts`` straight drifts in a row, drawn from ``rng``."""
    width = float(rng.uniform(*WIDTH_M))
    line = geo.bent_line(rng, drifts, BEND_DEG, LEG_M)
    cuts = _crosscuts(rng, line, width)
    db = float(rng.uniform(*ROCK_DB))
    walls = _side_walls(line, width, 1, cuts, db) + _side_walls(line, width, -1, cuts, db)
    end = geo.unit(line[-2], line[-1])
    walls.append(build.wall([geo.add(line[-1], geo.left(end), width / 2 + ROCK_T / 2),
                             geo.add(line[-1], geo.left(end), -(width / 2 + ROCK_T / 2))], ROCK_T, db))
    face = width / 2 + ROCK_T / 2
    walls.append(build.wall([(0.0, face), (0.0, FACE_HALF_M)], ROCK_T, db))
    walls.append(build.wall([(0.0, -face), (0.0, -FACE_HALF_M)], ROCK_T, db))
    dist, side = float(rng.uniform(10.0, 40.0)), 1.0 if rng.random() < 0.5 else -1.0
    station = Station("gcs", build.mm(-dist), build.mm(side * rng.uniform(0.0, width / 2 + 4.0)), 255,
                      round(float(rng.uniform(10.0, 20.0)), 1))
    radio = RadioParams(exponent=round(float(rng.uniform(1.6, 2.0)), 2),
                        shadowing_db=round(float(rng.uniform(2.0, 4.0)), 1),
                        fade_width_db=round(float(rng.uniform(3.0, 6.0)), 1))
    denied = _underground(line, cuts, width)
    start = (-float(rng.uniform(3.0, 6.0)), 0.0)
    stop = geo.add(line[-1], end, -(width / 2 + 1.5))  # short of the drift's end face
    description = (f"A generated mine: {drifts} drift{'s' if drifts > 1 else ''} {width:.1f} m wide with "
                   f"{len(cuts)} crosscut{'s' if len(cuts) != 1 else ''}; the operator stands off the portal's axis "
                   "and drives in until the rock takes the link away.")
    return build.scenario(KIND, description, walls, denied, station, radio, [start, *line[:-1], stop], SPEED)


def _underground(line: list[geo.Point], cuts, width: float) -> list[tuple[geo.Point, ...]]:
    """GPS-denied zones: each drift and crosscut as a rectangle a little wider than it, from 1 m inside the portal."""
    zones, w = [], width / 2 + 0.5
    for leg, (a, b) in enumerate(zip(line[:-1], line[1:], strict=True)):
        u = geo.unit(a, b)
        n = geo.left(u)
        a = geo.add(a, u, 1.0) if leg == 0 else geo.add(a, u, -w)
        b = geo.add(b, u, w)
        zones.append((geo.add(a, n, w), geo.add(b, n, w), geo.add(b, n, -w), geo.add(a, n, -w)))
        for c_leg, s, side, depth in cuts:
            if c_leg == leg:
                root = geo.add(line[leg], u, s)
                tip = geo.add(root, n, side * (width / 2 + depth + 0.5))
                zones.append((geo.add(root, u, w), geo.add(tip, u, w), geo.add(tip, u, -w), geo.add(root, u, -w)))
    return zones


def check_world(sc: Scenario) -> check.Verdict:
    """The validity check of every family (``sim.worlds.check``)."""
    return check.check(sc)
