"""From a family's drawing to a Scenario: the route, the resume route, the plan, the criteria, the bounds.

A family draws the place (walls, GPS-denied zones, the station, the radio) and the centre line the operator should
drive. This module turns that line into the operator's waypoints so that the driven path *is* the centre line: the
scripted operator turns for the next waypoint ``WAYPOINT_RADIUS`` before it reaches one (``sim.operator``), so each
waypoint is put that far beyond the corner along the way in, and the turn happens on the corner itself, not across
the inside of the bend (which, in a 1.2 m pipe, is a wall). The route ends a few metres past where the mean link
dies, so the operator does not keep pushing into a dead zone; the plan and criteria are the built-in worlds'
(``sim/scenarios/tunnel.toml``, ``building.toml``): return to link, then loiter, then return to launch; success is
a return that started, the link regained by the return, no collision, and rest near the link.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

from link.plan_items import LEASE_BOUNDARY, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, NAV_RETURN_TO_LINK
from link.radio import RadioParams
from sim.scenario import Criteria, Scenario
from sim.station_script import WAYPOINT_RADIUS
from sim.world import Station, Wall
from sim.worlds import check
from sim.worlds import geometry as geo
from vehicle.service import PlanItem

AFTER_DEATH = 3.0  # m of route past the place the mean link dies
DISPLACEMENT_SPARE = 10.0  # m the return may go beyond the straight line back to the link
LOITER_S = 20.0
CRITERIA = Criteria(return_started=True, link_regained=True, regained_by="return", max_final_target_error_m=6.0,
                    max_collisions=0, min_distance_back_m=1.0)


def mm(v: float) -> float:
    """A coordinate to the millimetre: files stay readable, and the world is what the file says."""
    return round(float(v), 3)


def pt(p: geo.Point) -> geo.Point:
    return mm(p[0]), mm(p[1])


def wall(points: Sequence[geo.Point], thickness: float, attenuation_db: float) -> Wall:
    return Wall(tuple(pt(p) for p in points), mm(thickness), round(float(attenuation_db), 1))


def waypoints(line: Sequence[geo.Point], speed: float) -> tuple[tuple[float, float, float], ...]:
    """Waypoints whose steered path (``check.steered_path``) from ``line[0]`` is ``line``: each one
    WAYPOINT_RADIUS beyond its corner along the way in."""
    out = []
    for a, b in zip(line[:-1], line[1:], strict=True):
        if math.dist(a, b) < 1e-6:
            continue
        x, y = geo.add(b, geo.unit(a, b), WAYPOINT_RADIUS)
        out.append((mm(x), mm(y), round(speed, 2)))
    return tuple(out)


def _dies_at(sc: Scenario, line: Sequence[geo.Point]) -> float | None:
    """How far along ``line`` the mean link dies for good: the first place from which it stays dead for
    AFTER_DEATH metres, or to the line's end (None: nowhere)."""
    radio, band = check.mean_radio(sc), check.band_db(sc.radio)
    total = geo.length(line)
    n = max(1, math.ceil(total / check.STEP))
    dead = [check.margin_db(sc, radio, geo.along(line, total * k / n)) <= -band for k in range(n + 1)]
    span = math.ceil(AFTER_DEATH / (total / n))
    for k in range(n + 1):
        if all(dead[k:k + span + 1]):
            return total * k / n
    return None


def _bounds(walls: Sequence[Wall], points: Sequence[geo.Point]) -> tuple[float, float, float, float]:
    xs = [p[0] for w in walls for p in w.points] + [p[0] for p in points]
    ys = [p[1] for w in walls for p in w.points] + [p[1] for p in points]
    return (math.floor(min(xs)) - 3.0, math.floor(min(ys)) - 3.0, math.ceil(max(xs)) + 3.0,
            math.ceil(max(ys)) + 3.0)


def plan(max_displacement: float) -> tuple[PlanItem, ...]:
    return (PlanItem(NAV_RETURN_TO_LINK, float(max_displacement)), PlanItem(LEASE_BOUNDARY),
            PlanItem(NAV_LOITER_TIME, LOITER_S), PlanItem(LEASE_BOUNDARY), PlanItem(NAV_RETURN_TO_LAUNCH))


def scenario(kind: str, description: str, walls: Sequence[Wall], denied, station: Station, radio: RadioParams,
             line: Sequence[geo.Point], speed: float, site=None) -> Scenario:
    """The scenario of a drawn place: ``line`` is the centre line to drive, from the start; the robot starts on
    ``line[0]`` facing ``line[1]`` (to the whole degree). ``site``: the map whose cells are the walls
    (``sim.maps``), if the place is one."""
    line = [pt(p) for p in line]
    yaw = math.radians(round(math.degrees(math.atan2(line[1][1] - line[0][1], line[1][0] - line[0][0]))))
    sc = Scenario(name=f"gen:{kind}", description=description, file=f"gen:{kind}", duration=120.0, seed=1,
                  vehicle="rover", bounds=_bounds(walls, [*line, (station.x, station.y)]), walls=tuple(walls),
                  denied=tuple(tuple(pt(p) for p in poly) for poly in denied), stations=(station,), radio=radio,
                  start=(line[0][0], line[0][1], yaw), operator_station=station.name, teleop="velocity",
                  route=waypoints(line, speed), resume_route=(), plan=plan(0.0), criteria=CRITERIA, site=site)
    dies = _dies_at(sc, line)
    if dies is not None:
        line = [pt(p) for p in geo.cut(line, min(geo.length(line), dies + AFTER_DEATH))]
    back = list(reversed(line))
    sc = replace(sc, route=waypoints(line, speed), resume_route=waypoints(back, min(1.5, speed * 1.2)))
    verdict = check.check(sc)
    reach = verdict.needed_displacement_m if verdict.needed_displacement_m is not None else 0.0
    duration = 2.5 * geo.length(line) / speed + LOITER_S + 90.0
    return replace(sc, plan=plan(5.0 * math.ceil((reach + DISPLACEMENT_SPARE) / 5.0)),
                    duration=float(min(900, 10 * math.ceil(duration / 10))))
