"""Does a world mean something? The validity check every generated world passes (docs/architecture.md §7.1).

Three questions, answered from the scenario alone, deterministically:

- *Drivable*: the path the scripted operator really drives (``steered_path``: it heads for each waypoint and turns
  for the next one ``WAYPOINT_RADIUS`` before it, so it cuts corners) keeps every wall's face at least half of
  (the widest robot's width + ``MARGIN``) from its centre line: a clear width of robot width + 0.3 m. The widest
  robot is taken (``sim.robots``: rover 0.70 m, legged 0.80 m), so a world drives with ``--vehicle legged`` too.
  The resume route is checked the same way, from the route's end.
- *The link*: the radio model of ``link.radio`` at its mean (shadowing left out) is alive at the route's start and
  dead somewhere along it: the route ends in a stretch where it is dead. "Alive" and "dead" each keep a margin of
  ``SIGMAS`` shadowing spreads plus half the fade width from the receiver's threshold, so the run's own shadowing
  field rarely turns one into the other.
- *The plan brings it back*: the first RETURN_TO_LINK may displace the robot at least as far as the straight line
  from the route's end back to the last place before the loss where the link was alive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from link.plan_items import NAV_RETURN_TO_LINK
from link.radio import Radio
from sim.robots import LeggedSpec, RoverSpec
from sim.station_script import WAYPOINT_RADIUS
from sim.worlds import geometry as geo
from vehicle.params import BY_NAME

MARGIN = 0.3  # m: clear width beyond the robot's own (docs/architecture.md §7.1)
ROBOT_WIDTH = 2 * max(RoverSpec.radius, LeggedSpec.radius)  # m: the widest robot
CLEARANCE = (ROBOT_WIDTH + MARGIN) / 2  # m: from the path's centre line to a wall's face
SIGMAS = 2.0  # shadowing spreads between "alive" / "dead" and the receiver's threshold
STEP = 0.25  # m: how finely the link is sampled along the path
# link/radio.py turns the margin into a delivery with exp(-margin / (fade_width / 4)), which overflows a float for
# a margin under about -177 fade widths: a run must never take the robot there (the check keeps a spare)
OVERFLOW_FADES = 120.0


@dataclass(frozen=True)
class Verdict:
    """What the check found; ``problems`` empty means valid."""

    problems: tuple[str, ...]
    clearance_m: float  # least distance from the driven path to a wall's face
    start_margin_db: float  # the link's mean margin over the receiver's threshold at the route's start
    dead_at: geo.Point | None  # where the dead stretch the route ends in begins
    alive_at: geo.Point | None  # the last place before that where it is alive
    needed_displacement_m: float | None  # from the route's end back to alive_at
    plan_displacement_m: float | None  # what the plan's first RETURN_TO_LINK allows

    @property
    def ok(self) -> bool:
        return not self.problems


def steered_path(start: geo.Point, route) -> list[geo.Point]:
    """Where the scripted operator drives: straight at each waypoint until within WAYPOINT_RADIUS, then on to the
    next (``sim.operator``), stopping WAYPOINT_RADIUS short of the last one. A kinematic sketch: the robot turns in
    place for a large heading error (``vehicle.teleop``), so it follows these straight lines closely."""
    path, here = [start], start
    for x, y, *_ in route:
        d = math.dist(here, (x, y))
        if d <= WAYPOINT_RADIUS:
            continue
        here = geo.add(here, geo.unit(here, (x, y)), d - WAYPOINT_RADIUS)
        path.append(here)
    return path


def clearance(path, walls) -> float:
    """The least distance from ``path`` to any wall's face (its capsule)."""
    best = math.inf
    for wall in walls:
        best = min(best, geo.polyline_distance(path, wall.points) - wall.thickness / 2)
    return best


def margin_db(sc, radio: Radio, p: geo.Point) -> float:
    """The mean RSSI at ``p`` from the operator's station over the receiver's threshold (dB)."""
    st = sc.station(sc.operator_station)
    try:
        state = radio.link((st.x, st.y), st.power_dbm, p)
    except OverflowError:  # link/radio.py's logistic overflows a few hundred dB under the threshold: dead
        return -math.inf
    return state.rssi_dbm - max(sc.radio.sensitivity_dbm, sc.radio.noise_floor_dbm + 5.0)


def mean_radio(sc) -> Radio:
    """The scenario's radio model without its shadowing: the mean channel, the same for every seed."""
    return Radio(replace(sc.radio, shadowing_db=0.0), sc.world().attenuation_db, 0)


def band_db(radio_params) -> float:
    """How far from the threshold "alive" and "dead" begin."""
    return SIGMAS * radio_params.shadowing_db + radio_params.fade_width_db / 2


def samples(path) -> list[geo.Point]:
    """Points every STEP metres along ``path``, its end included."""
    total = geo.length(path)
    n = max(1, math.ceil(total / STEP))
    return [geo.along(path, total * k / n) for k in range(n + 1)]


def plan_displacement(sc) -> float | None:
    """The first RETURN_TO_LINK's max displacement (0: the RTL_MAX_DISP parameter); None without one."""
    for item in sc.plan:
        if item.command == NAV_RETURN_TO_LINK:
            return item.param1 or sc.params.get("RTL_MAX_DISP", BY_NAME["RTL_MAX_DISP"].default)
    return None


def check(sc) -> Verdict:
    """The three questions of the module's docstring for scenario ``sc``."""
    problems = []
    path = steered_path(sc.start[:2], sc.route)
    resume = steered_path(path[-1], sc.resume_route) if sc.resume_route else [path[-1]]
    room = min(clearance(path, sc.walls), clearance(resume, sc.walls)) if sc.walls else math.inf
    if room < CLEARANCE:
        problems.append(f"the route passes {room:.2f} m from a wall; a robot {ROBOT_WIDTH:.2f} m wide with "
                        f"{MARGIN} m of margin needs {CLEARANCE:.2f} m")
    radio, band = mean_radio(sc), band_db(sc.radio)
    points = samples(path)
    margins = [margin_db(sc, radio, p) for p in points]
    deepest = min(margins)
    if deepest < -OVERFLOW_FADES * sc.radio.fade_width_db:
        problems.append(f"the link's margin falls to {deepest:.0f} dB on the route, where link/radio.py's delivery "
                        "curve overflows")
    if margins[0] < band:
        problems.append(f"the link at the route's start is {margins[0]:.1f} dB over the threshold; alive needs "
                        f"{band:.1f} dB")
    # the dead stretch the route ends in: where the operator is cut off for good (a link that flickers off and
    # on before it, through a doorway, is the world's business: the return handles it)
    tail = len(margins)
    while tail > 0 and margins[tail - 1] <= -band:
        tail -= 1
    dead_at = alive_at = needed = None
    if tail == len(margins):
        problems.append(f"the link is not dead where the route ends (margin {margins[-1]:.1f} dB; dead needs "
                        f"{-band:.1f} dB)" if min(margins) <= -band else
                        f"the link never dies along the route (least margin {min(margins):.1f} dB; dead needs "
                        f"{-band:.1f} dB)")
    else:
        dead_at = points[tail]
        alive = [k for k in range(tail) if margins[k] >= band]
        if not alive:
            problems.append("the link is never alive along the route before it dies")
        else:
            alive_at = points[alive[-1]]
            needed = math.dist(points[-1], alive_at)
    allowed = plan_displacement(sc)
    if allowed is None:
        problems.append("the plan has no RETURN_TO_LINK")
    elif needed is not None and allowed < needed:
        problems.append(f"the plan's return may go {allowed:g} m, the link is {needed:.1f} m back")
    return Verdict(tuple(problems), room, margins[0], dead_at, alive_at, needed, allowed)
