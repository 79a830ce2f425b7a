"""Culverts: a concrete pipe under an embankment, bending on its way, the operator at its mouth.

The operator stands in front of the headwall and drives the robot in; past the bends the pipe's walls and the
fill behind them take the link away (``sim/scenarios/culvert.toml`` is the hand-drawn one). The far end is closed
(a grate or silt, as culverts that need a robot's inspection often are).

Where the figures come from:

- Pipes 1.2-3.6 m (docs/architecture.md §7.1): the standard reinforced-concrete pipe sizes of ASTM C76 from 48 to 144 in
  internal diameter (1.22, 1.52, 1.83, 2.13, 2.44, 2.74, 3.05, 3.66 m). The plan view takes the diameter as the
  clear width: the robot drives the invert of a round pipe, where the floor is narrower, so this flatters the
  narrow pipes. Walls about D/12 + 25 mm thick (the usual "Wall B" rule: wall in inches = diameter in feet + 1).
- Bends of 30-90 degrees between straight runs 6-15 m long: a change of direction in a drain is made at a
  junction or a mitred bend; 90 degrees is the most any one makes. One pipe size throughout.
- 15-30 dB each time a radio path crosses the pipe's wall: concrete of that thickness loses roughly 10-20 dB at
  2.4 GHz in typical published measurements (ITU-R P.2040 gives concrete's electrical properties), and the earth
  fill behind it more: typical, not measured.
- The headwall and the embankment's face 30-50 dB: a path into the pipe other than through its mouth crosses the
  fill (``culvert.toml`` takes 40 dB).
- Path-loss exponent 2.0-2.2, shadowing 1-2 dB: short concrete paths, as in ``culvert.toml``.
- The station 3-15 m in front of the mouth, up to 3 m to the side, 10-27 dBm (``culvert.toml``: 27 dBm at 4 m).
"""

from __future__ import annotations

import numpy as np

from link.radio import RadioParams
from sim.scenario import Scenario
from sim.world import Station
from sim.worlds import build, check
from sim.worlds import geometry as geo

KIND = "culvert"
SIZES = {"bends": (1, 4)}
PIPES_M = (1.22, 1.52, 1.83, 2.13, 2.44, 2.74, 3.05, 3.66)  # ASTM C76: 48, 60, 72, 84, 96, 108, 120, 144 in
BEND_DEG = (30.0, 90.0)
RUN_M = (6.0, 15.0)
PIPE_DB = (15.0, 30.0)
FILL_DB = (30.0, 50.0)
FACE_HALF_M = 12.0  # m of embankment face either side of the mouth
FACE_T = 0.4  # m: the headwall's thickness


def generate(rng: np.random.Generator, bends: int) -> Scenario:
    """One culvert with ``bends`` bends, drawn from ``rng``."""
    pipe = float(rng.choice(PIPES_M))
    thick = pipe / 12 + 0.025
    line = geo.bent_line(rng, bends + 1, BEND_DEG, RUN_M)
    pipe_db, fill_db = float(rng.uniform(*PIPE_DB)), float(rng.uniform(*FILL_DB))
    d = pipe / 2 + thick / 2
    walls = [build.wall(geo.offset(line, d), thick, pipe_db), build.wall(geo.offset(line, -d), thick, pipe_db)]
    end = geo.unit(line[-2], line[-1])
    walls.append(build.wall([geo.add(line[-1], geo.left(end), d), geo.add(line[-1], geo.left(end), -d)], thick,
                            pipe_db))
    face = pipe / 2 + FACE_T / 2  # the face's round end flush with the pipe's inside, not into the mouth
    walls.append(build.wall([(0.0, face), (0.0, FACE_HALF_M)], FACE_T, fill_db))
    walls.append(build.wall([(0.0, -face), (0.0, -FACE_HALF_M)], FACE_T, fill_db))
    station = Station("gcs", build.mm(-rng.uniform(3.0, 15.0)), build.mm(rng.uniform(-3.0, 3.0)), 255,
                      round(float(rng.uniform(10.0, 27.0)), 1))
    radio = RadioParams(exponent=round(float(rng.uniform(2.0, 2.2)), 2),
                        shadowing_db=round(float(rng.uniform(1.0, 2.0)), 1),
                        fade_width_db=round(float(rng.uniform(3.0, 6.0)), 1))
    inside = [(0.5, 0.0), *line[1:]]  # from just inside the mouth
    denied = [tuple(geo.offset(inside, pipe / 2 + 0.2)) + tuple(reversed(geo.offset(inside, -(pipe / 2 + 0.2))))]
    start = (min(-1.5, station.x / 2), 0.0)
    stop = geo.add(line[-1], end, -(pipe / 2 + 1.0))
    speed = round(min(0.9, 0.3 + 0.2 * pipe), 2)  # slower in a narrow pipe, where a turn leaves little room
    description = (f"A generated culvert: a {pipe:.2f} m pipe with {bends} bend{'s' if bends > 1 else ''} under an "
                   "embankment; the operator at the mouth drives in until the pipe's walls take the link away.")
    return build.scenario(KIND, description, walls, denied, station, radio, [start, *line[:-1], stop], speed)


def check_world(sc: Scenario) -> check.Verdict:
    """The validity check of every family (``sim.worlds.check``)."""
    return check.check(sc)
