"""A Scenario written back as a scenario file: ``world.toml`` of ``returnlink sim world``.

The file is an ordinary scenario (no ``[generate]``; a map world keeps its ``[map]`` table, naming the map
by its resolved path and its content's digest, with the stations written in the world frame): reading it back
with ``sim.scenario.parse`` gives the same Scenario, field for field, so ``sim run world.toml --seed N`` flies
exactly the run ``sim run gen:KIND --seed N`` flew. Floats are written with ``repr`` (the shortest text that
reads back as the same double), and the start's heading, kept in radians but written in degrees, as the degrees
that convert back to the very same radians.
"""

from __future__ import annotations

import json
import math
from dataclasses import fields

from sim.scenario import PLAN_COMMANDS, PLAN_KEYS, Scenario

_NAMES = {v: k for k, v in PLAN_COMMANDS.items()}


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} to a scenario file")


def _degrees(yaw: float) -> float:
    """Degrees that ``math.radians`` turns back into ``yaw`` exactly (the plain conversion, or a neighbour)."""
    d = math.degrees(yaw)
    for _ in range(64):
        if math.radians(d) == yaw:
            return d
        d = math.nextafter(d, math.inf if math.radians(d) < yaw else -math.inf)
    return math.degrees(yaw)


def _plan_item(item) -> str:
    keys = {"command": _NAMES[item.command]}
    values = (item.param1, item.param2, item.param3, item.param4, item.x, item.y)
    for key, index in PLAN_KEYS.get(item.command, {}).items():
        keys[key] = float(values[index - 1])
    return "{ " + ", ".join(f"{k} = {_value(v)}" for k, v in keys.items()) + " }"


def to_toml(sc: Scenario) -> str:
    """The scenario file of ``sc``."""
    out = [f"name = {_value(sc.name)}", f"description = {_value(sc.description)}",
           f"duration = {_value(float(sc.duration))}", f"seed = {sc.seed}", f"vehicle = {_value(sc.vehicle)}", "",
           *_map(sc), "[world]", f"bounds = {_value([float(b) for b in sc.bounds])}"]
    out += _world(sc)
    out += ["", "[radio]"] + [f"{f.name} = {_value(getattr(sc.radio, f.name))}" for f in fields(sc.radio)]
    out += ["", "[start]", f"position = {_value([sc.start[0], sc.start[1]])}",
            f"yaw_deg = {_value(_degrees(sc.start[2]))}"]
    out += _operator(sc)
    for e in sc.events:
        out += ["", "[[events]]"] + [f"{f.name} = {_value(getattr(e, f.name))}" for f in fields(e)]
    crit = [(f.name, getattr(sc.criteria, f.name)) for f in fields(sc.criteria)]
    out += ["", "[criteria]"] + [f"{k} = {_value(list(v) if isinstance(v, tuple) else v)}" for k, v in crit
                                 if v is not None]
    return "\n".join(out) + "\n"


def _map(sc: Scenario) -> list[str]:
    """[map] of a map world, whose walls are the map's cells, named by file and content; nothing for others."""
    if sc.site is None:
        return []
    site = sc.site
    return ["[map]", f"file = {_value(site.file)}", f"unknown = {_value(site.unknown)}",
            f"wall_db = {_value(float(site.wall_db))}",
            f"wall_db_per_m = {_value(float(site.wall_db_per_m))}", f"digest = {_value(site.digest)}", ""]


def _world(sc: Scenario) -> list[str]:
    """The walls, radio-denied zones and ground stations of [world]."""
    out: list[str] = []
    for w in sc.walls:
        out += ["", "[[world.walls]]", f"points = {_value([list(p) for p in w.points])}",
                f"thickness = {_value(float(w.thickness))}", f"attenuation_db = {_value(float(w.attenuation_db))}"]
    for poly in sc.denied:
        out += ["", "[[world.denied]]", f"polygon = {_value([list(p) for p in poly])}"]
    for s in sc.stations:
        out += ["", "[[world.stations]]", f"name = {_value(s.name)}", f"position = {_value([s.x, s.y])}",
                f"sysid = {s.sysid}", f"power_dbm = {_value(float(s.power_dbm))}"]
    return out


def _operator(sc: Scenario) -> list[str]:
    """[operator]: the station it drives from, its route, its return plan and the vehicle parameters it sets."""
    out = ["", "[operator]", f"station = {_value(sc.operator_station)}", f"teleop = {_value(sc.teleop)}",
           f"route = {_value([list(p) for p in sc.route])}"]
    if sc.resume_route:
        out.append(f"resume_route = {_value([list(p) for p in sc.resume_route])}")
    out += [f"attempts = {sc.attempts}", f"rejoin = {_value(sc.rejoin)}",
            "plan = [" + "".join(f"\n  {_plan_item(i)}," for i in sc.plan) + ("\n]" if sc.plan else "]")]
    if sc.params:
        out.append("params = { " + ", ".join(f"{k} = {_value(float(v))}" for k, v in sc.params.items()) + " }")
    return out
