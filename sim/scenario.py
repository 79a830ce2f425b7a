"""Scenario files (TOML): the place, the robot, the operator's script and what counts as success.

Every error names the file, the line and the field, because a scenario is written by hand: an unknown key
(with the closest known one), NaN or infinity anywhere, a value out of its range, a vehicle parameter the vehicle
would refuse. A misspelt key silently ignored is a scenario that does not test what its author thinks it tests.

A file may instead hold ``[generate]`` (docs/architecture.md §7.1): a world family's ``kind`` and size fields, the
world drawn from the run's seed. This module reads and range-checks that table (``read_generate``) with the same
errors; the families and the drawing are ``sim.worlds``'s, which imports this module (``sim.worlds.resolve`` loads
any name).
"""

from __future__ import annotations

import difflib
import math
import re
import sys
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

from link.plan_items import (
    LEASE_BOUNDARY,
    LOCAL_FRAMES,
    MISSION_FRAME,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_RETURN_TO_LINK,
    NAV_WAYPOINT,
    check_fields,
)
from link.radio import RadioParams
from sim.maps import mapfile
from sim.maps.grid import DEFAULT_WALL_DB, DEFAULT_WALL_DB_PER_M, UNKNOWN, Site
from sim.registry import NATIVE_VEHICLES
from sim.scenario_fields import Reader, ScenarioError
from sim.world import Station, Wall, World
from vehicle.lease import ExpireReason
from vehicle.params import BY_NAME, ParamError, validate
from vehicle.service import PlanItem

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

BUILTIN = ("tunnel", "warehouse", "loop", "open", "handover", "building", "culvert")
# scenario names for the mission items of a return plan
PLAN_COMMANDS = {"RETURN_TO_LINK": NAV_RETURN_TO_LINK, "BOUNDARY": LEASE_BOUNDARY, "LOITER": NAV_LOITER_TIME,
                 "RETURN_TO_LAUNCH": NAV_RETURN_TO_LAUNCH, "WAYPOINT": NAV_WAYPOINT}
EVENT_ACTIONS = ("jam", "unjam", "kill_gcs", "revive_gcs", "power", "takeover", "rtl", "param", "claim", "stop")
STATION_POWER_DBM = (-30.0, 40.0)  # a station's transmit power ([[world.stations]] power_dbm)
POWER_STEP_DB = STATION_POWER_DBM[1] - STATION_POWER_DBM[0]  # the largest change a "power" event may make
# the keys of each plan command, by the field of link.plan_items.KINDS they fill (1..4 = param1..4, 5/6 = x/y)
PLAN_KEYS = {NAV_RETURN_TO_LINK: {"max_displacement": 1, "speed": 2, "target": 3, "on_regain": 4},
             NAV_LOITER_TIME: {"time": 1}, NAV_WAYPOINT: {"x": 5, "y": 6}}
SEED_MAX = 2**32 - 1
# what a file with [generate] may hold beside it: the rest of the scenario is generated with the world
GENERATE_KEYS = ("name", "description", "duration", "seed", "vehicle", "generate")
# [map] (docs/architecture.md §7.2): the map_server YAML, the station in the map's frame, the grid's radio loss
MAP_KEYS = ("file", "station", "power_dbm", "unknown", "wall_db", "wall_db_per_m", "digest")
MAP_LOSS = ("wall_db", "wall_db_per_m")  # what a [radio] table may add for a map world (what `site fit` writes)
# what a file with [map] and no [operator] may hold: the operator's route is drawn on the map from the seed
MAP_WORLD_KEYS = ("name", "description", "duration", "seed", "vehicle", "map", "radio")


@dataclass(frozen=True)
class Event:
    t: float
    action: str
    duration: float = 0.0
    station: str = ""
    name: str = ""
    value: float = 0.0


@dataclass(frozen=True)
class Criteria:
    return_started: bool | None = None
    link_regained: bool | None = None
    max_final_target_error_m: float | None = None
    max_collisions: int = 0
    max_displacement_respected: bool = True
    min_distance_back_m: float | None = None
    min_commands_rejected: int = 0
    chain_reasons: tuple[str, ...] = ()
    regained_by: str | None = None  # "return" or "operator": who must have brought the link back (metrics §7)


REGAINED_BY = ("return", "operator")


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    file: str
    duration: float
    seed: int
    vehicle: str
    bounds: tuple[float, float, float, float]
    walls: tuple[Wall, ...]
    denied: tuple[tuple[tuple[float, float], ...], ...]
    stations: tuple[Station, ...]
    radio: RadioParams
    start: tuple[float, float, float]
    operator_station: str
    teleop: str
    route: tuple[tuple[float, float, float], ...]
    resume_route: tuple[tuple[float, float, float], ...]
    plan: tuple[PlanItem, ...]
    attempts: int = 2  # operator.attempts: how often the operator drives toward a place where the link died
    rejoin: bool = True  # operator.rejoin: after a return, pick the resume route up at the leg the robot is on
    params: dict[str, float] = field(default_factory=dict)
    events: tuple[Event, ...] = ()
    criteria: Criteria = Criteria()
    site: Site | None = None  # a map whose cells are the walls (docs/architecture.md §7.2), or None

    def world(self) -> World:
        if self.site is not None:
            return self.site.world(self.denied, self.stations)
        return World(self.walls, self.denied, self.stations)

    def station(self, name: str) -> Station:
        for s in self.stations:
            if s.name == name:
                return s
        raise KeyError(name)


def parse(text: str, file: str = "<scenario>") -> Scenario:
    """A scenario from TOML text; ScenarioError (file, line, field) for anything wrong. One part per table."""
    raw, r = _load_toml(text, file)
    if "generate" in raw:
        raise ScenarioError(file, _header_line(r, "generate"), "generate", "a generated world: read it with "
                            "sim.worlds.resolve (returnlink sim run, sim world and sim sweep do)")
    r.known(raw, "", ("name", "description", "duration", "seed", "vehicle", "world", "radio", "start", "operator",
                      "events", "criteria", "map"))
    r.finite(raw, "")
    name = r.get(raw, "name", "name", str)
    vehicle, seed = _vehicle_and_seed(r, raw)
    mt = read_map(r, raw, file)
    if mt is not None and "operator" not in raw:
        raise ScenarioError(file, _header_line(r, "map"), "map", "a map world without [operator]: its route is "
                            "drawn from the seed; read it with sim.worlds.resolve (returnlink sim run, sim world and "
                            "sim sweep do)")
    bounds, walls, denied, stations = _world(r, raw, mt)
    op = _operator(r, raw, stations)
    radio, loss = _radio(r, raw, MAP_LOSS if mt else ())
    return Scenario(
        name=name, description=r.get(raw, "description", "description", str, ""), file=file,
        duration=r.number(raw, "duration", "duration", lo=1.0, hi=36000.0),
        seed=seed, vehicle=vehicle, bounds=bounds, walls=walls, denied=denied, stations=stations,
        radio=radio, start=_start(r, raw), **op, events=_events(r, raw, stations),
        criteria=_criteria(r, raw), site=replace(mt.site, **loss) if mt else None,
    )


@dataclass(frozen=True)
class MapTable:
    """A scenario's ``[map]`` table, checked: the map (a Site) and the station it names (world frame), if any."""

    site: Site
    station: Station | None
    line: int | None


def read_map(r: Reader, raw: dict, file: str) -> MapTable | None:
    """``[map]``: the map_server YAML (relative to the scenario file), read now so a bad map is an error at this
    line; the station (map frame, x east y north) turned into the world frame (north, east) and checked against
    the map's cells."""
    if "map" not in raw:
        return None
    m = r.table(raw, "map", "map", MAP_KEYS)
    name = r.get(m, "file", "map.file", str)
    path = Path(name)
    if not path.is_absolute():
        path = (Path(file).parent if file and not file.startswith(("<", "map:")) else Path(".")) / name
    unknown = r.get(m, "unknown", "map.unknown", str, "wall")
    if unknown not in UNKNOWN:
        raise r.fail("map.unknown", f"must be one of {', '.join(UNKNOWN)}, got {unknown!r}")
    wall_db = r.number(m, "wall_db", "map.wall_db", DEFAULT_WALL_DB, 0.0, 200.0)
    per_m = r.number(m, "wall_db_per_m", "map.wall_db_per_m", DEFAULT_WALL_DB_PER_M, 0.0, 200.0)
    digest = r.get(m, "digest", "map.digest", str, "")
    try:
        occupancy = mapfile.read(path)
    except mapfile.MapError as e:
        raise r.fail("map.file", str(e)) from None
    if digest and digest != occupancy.digest:
        raise r.fail("map.digest", f"the map {path} has changed since this world was written (its content is "
                                   f"{occupancy.digest} now, {digest} then)")
    site = Site(str(path.resolve()), unknown, wall_db, per_m, occupancy.digest)
    station = None
    if "station" in m:
        x, y = r.point(r.get(m, "station", "map.station", list), "map.station")
        station = Station("gcs", y, x, 255, r.number(m, "power_dbm", "map.power_dbm", 20.0, *STATION_POWER_DBM))
        problem = site.grid().station_problem(station.x, station.y)
        if problem:
            raise r.fail("map.station", f"the station at x {x:g}, y {y:g} (map frame) {problem} of {path}")
    return MapTable(site, station, _header_line(r, "map"))


@dataclass(frozen=True)
class MapWorld:
    """A file with ``[map]`` and no ``[operator]``: the map, the station, the radio and what the file sets; the
    route is drawn per seed (``sim.worlds.map_routes``)."""

    file: str
    table: MapTable
    radio: RadioParams
    seed: int
    vehicle: str
    name: str
    description: str | None = None
    duration: float | None = None


def read_map_world(text: str, file: str) -> MapWorld | None:
    """The map world of a scenario file with ``[map]`` and no ``[operator]``, every field checked by file, line
    and field; None for any other file."""
    raw, r = _load_toml(text, file)
    if "map" not in raw or "operator" in raw:
        return None
    r.known(raw, "", MAP_WORLD_KEYS)
    r.finite(raw, "")
    mt = read_map(r, raw, file)
    if mt.station is None:
        raise r.fail("map.station", "is required: where the operator's station stands (map frame, metres: x east, "
                                    "y north), from which the route is drawn")
    radio, loss = _radio(r, raw, MAP_LOSS)
    vehicle, seed = _vehicle_and_seed(r, raw)
    name = r.get(raw, "name", "name", str, f"map:{Path(mt.site.file).stem}")
    return MapWorld(file, replace(mt, site=replace(mt.site, **loss)), radio, seed, vehicle, name,
                    r.get(raw, "description", "description", str, None),
                    r.number(raw, "duration", "duration", None, lo=1.0, hi=36000.0))


def read_radio_file(path: str) -> tuple[dict[str, float], dict[str, float]]:
    """A ``--radio FILE``'s ``[radio]`` table (what `site fit` writes): the radio model's fields and the map's
    wall loss, each checked by file, line and field."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(path, None, "", f"cannot read the radio file: {getattr(e, 'strerror', None) or e}") \
            from None
    raw, r = _load_toml(text, path)
    r.known(raw, "", ("radio",))
    r.finite(raw, "")
    if "radio" not in raw:
        raise ScenarioError(path, None, "radio", "is required: a [radio] table (returnlink site fit writes one)")
    radio, loss = _radio(r, raw, MAP_LOSS)
    given = r.get(raw, "radio", "radio", dict)
    return ({k: getattr(radio, k) for k in given if k in RadioParams.__dataclass_fields__},
            {k: v for k, v in loss.items() if k in given})


def _load_toml(text: str, file: str) -> tuple[dict, Reader]:
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        m = re.search(r"line (\d+)", str(e))
        raise ScenarioError(file, int(m.group(1)) if m else None, "", f"not valid TOML: {e}") from None
    return raw, Reader(file, text)


def _header_line(r: Reader, table: str) -> int | None:
    """The line of ``[table]`` (or ``[[table]]``, ``[table.x]``)."""
    header = re.compile(rf"^\s*\[+\s*{re.escape(table)}\s*[.\]]")
    return next((i + 1 for i, ln in enumerate(r.lines) if header.match(ln)), None)


def _vehicle_and_seed(r: Reader, raw: dict) -> tuple[str, int]:
    """The robot and the seed a scenario (drawn or generated) flies with, range-checked."""
    vehicle = r.get(raw, "vehicle", "vehicle", str, "rover")
    if vehicle not in NATIVE_VEHICLES:  # a scenario's own robot: an autopilot is asked for by --vehicle
        raise r.fail("vehicle", f"must be {' or '.join(NATIVE_VEHICLES)}, got {vehicle!r}")
    seed = r.get(raw, "seed", "seed", int, 1)
    if not 0 <= seed <= SEED_MAX:
        raise r.fail("seed", f"must be within 0..{SEED_MAX}, got {seed}")
    return vehicle, seed


def _world(r: Reader, raw: dict, mt: MapTable | None = None) -> tuple[tuple[float, ...], tuple[Wall, ...], tuple,
                                                                      tuple[Station, ...]]:
    """[world]: bounds, walls, radio-denied zones and ground stations. A map world's walls are its cells, its
    bounds the map's unless given, and its [map] station is the first station."""
    world = r.table(raw, "world", "world", ("bounds", "walls", "denied", "stations"), {} if mt else ...)
    if mt is not None and world.get("walls"):
        raise r.fail("world.walls", "a map world's walls are its occupied cells: draw them on the map")
    b = _bounds(r, world, mt)
    walls = _walls(r, world)
    denied = tuple(r.points(z, "polygon", f"world.denied[{k}].polygon", min_len=3)
                   for k, z in enumerate(r.tables(world, "denied", "world.denied", ("polygon",))))
    return b, walls, denied, _stations(r, world, mt)


def _bounds(r: Reader, world: dict, mt: MapTable | None) -> tuple[float, ...]:
    """[world] bounds: [xmin, ymin, xmax, ymax]; a map world's default to the map's, rounded out to the metre."""
    if mt is not None and "bounds" not in world:
        g = mt.site.grid().bounds()
        world = {**world, "bounds": [math.floor(g[0]), math.floor(g[1]), math.ceil(g[2]), math.ceil(g[3])]}
    b = r.get(world, "bounds", "world.bounds", list)
    if len(b) != 4 or not all(isinstance(c, (int, float)) for c in b) or b[0] >= b[2] or b[1] >= b[3]:
        raise r.fail("world.bounds", "must be [xmin, ymin, xmax, ymax] with min < max")
    return tuple(float(c) for c in b)


def _walls(r: Reader, world: dict) -> tuple[Wall, ...]:
    """[[world.walls]]: polylines with a thickness and a radio loss; no segment of zero length."""
    walls = []
    for k, w in enumerate(r.tables(world, "walls", "world.walls", ("points", "thickness", "attenuation_db"))):
        p = f"world.walls[{k}]"
        points = r.points(w, "points", f"{p}.points")
        for j in range(1, len(points)):
            if points[j] == points[j - 1]:
                raise r.fail(f"{p}.points", f"points {j - 1} and {j} are the same: a wall of zero length")
        walls.append(Wall(points, r.number(w, "thickness", f"{p}.thickness", 0.5, 0.01, 20.0),
                          r.number(w, "attenuation_db", f"{p}.attenuation_db", 20.0, 0.0, 200.0)))
    return tuple(walls)


def _stations(r: Reader, world: dict, mt: MapTable | None) -> tuple[Station, ...]:
    """[[world.stations]]: at least one ground station; a map world's [map] station first unless named here."""
    stations = []
    for k, s in enumerate(r.tables(world, "stations", "world.stations", ("name", "position", "sysid", "power_dbm"))):
        p = f"world.stations[{k}]"
        x, y = r.point(r.get(s, "position", f"{p}.position", list), f"{p}.position")
        sysid = r.get(s, "sysid", f"{p}.sysid", int, 255)
        if not 1 <= sysid <= 255:
            raise r.fail(f"{p}.sysid", f"must be 1..255, got {sysid}")
        stations.append(Station(r.get(s, "name", f"{p}.name", str), x, y, sysid,
                                r.number(s, "power_dbm", f"{p}.power_dbm", 20.0, *STATION_POWER_DBM)))
    if mt is not None and mt.station is not None and mt.station.name not in {s.name for s in stations}:
        stations.insert(0, mt.station)
    if not stations:
        raise r.fail("world.stations", "needs at least one ground station")
    return tuple(stations)


def _radio(r: Reader, raw: dict, extra: tuple[str, ...] = ()) -> tuple[RadioParams, dict[str, float]]:
    """[radio]: the radio model's parameters (any left out keep their defaults), and those of ``extra`` (a map
    world's wall loss, dB) that it gives."""
    radio_raw = r.table(raw, "radio", "radio", (*RadioParams.__dataclass_fields__, *extra), {})
    radio_kw = {}
    for fname in RadioParams.__dataclass_fields__:
        if fname in radio_raw:
            flag = isinstance(getattr(RadioParams, fname), bool)  # an option (reorder), not a number
            radio_kw[fname] = (r.get(radio_raw, fname, f"radio.{fname}", bool) if flag
                               else r.number(radio_raw, fname, f"radio.{fname}"))
    more = {k: r.number(radio_raw, k, f"radio.{k}", lo=0.0, hi=200.0) for k in extra if k in radio_raw}
    return RadioParams(**radio_kw), more


def _start(r: Reader, raw: dict) -> tuple[float, float, float]:
    """[start]: where the robot boots, and its heading."""
    start_raw = r.table(raw, "start", "start", ("position", "yaw_deg"))
    sx, sy = r.point(r.get(start_raw, "position", "start.position", list), "start.position")
    return sx, sy, math.radians(r.number(start_raw, "yaw_deg", "start.yaw_deg", 0.0, -360, 360))


def _operator(r: Reader, raw: dict, stations: tuple[Station, ...]) -> dict:
    """[operator]: the scripted operator's station, teleop kind, route, attempts, rejoin, return plan and
    parameters (the Scenario fields they fill, by name)."""
    op = r.table(raw, "operator", "operator", ("station", "teleop", "route", "resume_route", "plan", "params",
                                                  "attempts", "rejoin"))
    op_station = r.get(op, "station", "operator.station", str, stations[0].name)
    if op_station not in {s.name for s in stations}:
        raise r.fail("operator.station", f"no station named {op_station!r}")
    teleop = r.get(op, "teleop", "operator.teleop", str, "velocity")
    if teleop not in ("velocity", "manual"):
        raise r.fail("operator.teleop", f"must be velocity or manual, got {teleop!r}")
    route = r.points(op, "route", "operator.route", n=3, min_len=1)
    attempts = r.get(op, "attempts", "operator.attempts", int, 2)
    if not 1 <= attempts <= 1000:
        raise r.fail("operator.attempts", f"must be in [1, 1000], got {attempts}")
    rejoin = r.get(op, "rejoin", "operator.rejoin", bool, True)
    resume = r.points(op, "resume_route", "operator.resume_route", n=3, min_len=1) if "resume_route" in op else ()
    for p in (*route, *resume):
        if not 0 < p[2] <= 5:
            raise r.fail("operator.route", f"speed must be in (0, 5] m/s, got {p[2]}")
    params_raw = r.get(op, "params", "operator.params", dict, {})
    params = {k: _param(r, k, r.number(params_raw, k, f"operator.params.{k}"), f"operator.params.{k}")
              for k in params_raw}
    return {"operator_station": op_station, "teleop": teleop, "route": route, "resume_route": resume,
            "attempts": attempts, "rejoin": rejoin, "plan": _plan(r, op), "params": params}


def _plan(r: Reader, op: dict) -> tuple[PlanItem, ...]:
    """operator.plan: the return plan, each item checked against the one table of plan-item ranges."""
    plan = []
    for k, it in enumerate(r.get(op, "plan", "operator.plan", list, [])):
        p = f"operator.plan[{k}]"
        if not isinstance(it, dict):
            raise r.fail(p, "must be a table like {command = \"RETURN_TO_LINK\"}")
        cmd = r.get(it, "command", f"{p}.command", str)
        if cmd not in PLAN_COMMANDS:
            raise r.fail(f"{p}.command", f"unknown plan command {cmd!r} (one of {', '.join(PLAN_COMMANDS)})")
        num = PLAN_COMMANDS[cmd]
        r.known(it, p, ("command", *PLAN_KEYS.get(num, ())))
        if num == NAV_RETURN_TO_LINK:
            plan.append(PlanItem(num, r.number(it, "max_displacement", f"{p}.max_displacement", 0.0, 0, 10000),
                                 r.number(it, "speed", f"{p}.speed", 0.0, 0, 5),
                                 r.number(it, "target", f"{p}.target", -1.0, -1, 2),
                                 r.number(it, "on_regain", f"{p}.on_regain", -1.0, -1, 1)))
        elif num == NAV_LOITER_TIME:
            plan.append(PlanItem(num, r.number(it, "time", f"{p}.time", lo=0, hi=3600)))
        elif num == NAV_WAYPOINT:
            plan.append(PlanItem(num, x=r.number(it, "x", f"{p}.x"), y=r.number(it, "y", f"{p}.y")))
        else:
            plan.append(PlanItem(num))
        _check_plan_item(r, plan[-1], p)
    return tuple(plan)


def _events(r: Reader, raw: dict, stations: tuple[Station, ...]) -> tuple[Event, ...]:
    """[[events]]: timed events, in time order."""
    events = []
    for k, ev in enumerate(r.tables(raw, "events", "events", ("t", "action", "duration", "station", "name",
                                                                "value"))):
        p = f"events[{k}]"
        action = r.get(ev, "action", f"{p}.action", str)
        if action not in EVENT_ACTIONS:
            raise r.fail(f"{p}.action", f"unknown action {action!r} (one of {', '.join(EVENT_ACTIONS)})")
        st = r.get(ev, "station", f"{p}.station", str, "")
        if st and st not in {s.name for s in stations}:
            raise r.fail(f"{p}.station", f"no station named {st!r}")
        event = Event(r.number(ev, "t", f"{p}.t", lo=0.0), action,
                      r.number(ev, "duration", f"{p}.duration", 0.0, 0.0), st,
                      r.get(ev, "name", f"{p}.name", str, ""), r.number(ev, "value", f"{p}.value", 0.0))
        if action == "param":
            _param(r, event.name, event.value, f"{p}.name")
        elif action == "power":
            # the station's transmit power changes by ``value`` dB (its range shrinks or grows: a station carried
            # back from the edge, a battery saver, an antenna knocked over). A change, not a level, so it means the
            # same on top of a campaign's power_dbm axis
            if "value" not in ev:
                raise r.fail(f"{p}.value", "a power event needs the change in the station's transmit power (dB)")
            r.number(ev, "value", f"{p}.value", lo=-POWER_STEP_DB, hi=POWER_STEP_DB)
        events.append(event)
    return tuple(sorted(events, key=lambda e: e.t))


def _criteria(r: Reader, raw: dict) -> Criteria:
    """[criteria]: what a run must show to pass."""
    crit_raw = r.table(raw, "criteria", "criteria", Criteria.__dataclass_fields__, {})
    reasons = r.get(crit_raw, "chain_reasons", "criteria.chain_reasons", list, [])
    for reason in reasons:
        if reason not in ExpireReason.__members__:
            raise r.fail("criteria.chain_reasons", f"unknown reason {reason!r} "
                                                   f"(one of {', '.join(ExpireReason.__members__)})")
    crit = Criteria(
        r.get(crit_raw, "return_started", "criteria.return_started", bool, None),
        r.get(crit_raw, "link_regained", "criteria.link_regained", bool, None),
        r.number(crit_raw, "max_final_target_error_m", "criteria.max_final_target_error_m", None, 0),
        int(r.number(crit_raw, "max_collisions", "criteria.max_collisions", 0, 0)),
        r.get(crit_raw, "max_displacement_respected", "criteria.max_displacement_respected", bool, True),
        r.number(crit_raw, "min_distance_back_m", "criteria.min_distance_back_m", None, 0),
        int(r.number(crit_raw, "min_commands_rejected", "criteria.min_commands_rejected", 0, 0)),
        tuple(reasons),
        r.get(crit_raw, "regained_by", "criteria.regained_by", str, None),
    )
    if crit.regained_by is not None and crit.regained_by not in REGAINED_BY:
        raise r.fail("criteria.regained_by", f"must be one of {', '.join(REGAINED_BY)}, got {crit.regained_by!r}")
    return crit


def _check_plan_item(r: Reader, item: PlanItem, path: str) -> None:
    """The same field ranges the vehicle checks a mission item against (link/plan_items.py)."""
    frame = LOCAL_FRAMES[0] if item.command == NAV_WAYPOINT else MISSION_FRAME
    fault = check_fields(item.command, frame, (item.param1, item.param2, item.param3, item.param4, item.x, item.y,
                                               0.0))
    if fault is not None:
        keys = {v: k for k, v in PLAN_KEYS.get(item.command, {}).items()}
        raise r.fail(f"{path}.{keys[fault.field]}" if fault.field in keys else path, fault.message)


def _param(r: Reader, name: str, value: float, path: str) -> float:
    """A vehicle parameter as the vehicle would take it: a known name, within its range."""
    if name not in BY_NAME:
        close = difflib.get_close_matches(name, list(BY_NAME), 1, 0.6)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise r.fail(path, f"no vehicle parameter {name!r}{hint}")
    try:
        return validate(name, value)
    except ParamError as e:
        raise r.fail(path, str(e)) from None


@dataclass(frozen=True)
class Generate:
    """A file's ``[generate]`` table, checked: the family, its size fields given, and what the file sets on top of
    the generated scenario (None: the generator's own)."""

    file: str
    line: int | None  # of the [generate] table, for errors found later (no valid draw)
    kind: str
    sizes: dict[str, int]
    seed: int  # the file's own; a run's --seed draws another world
    vehicle: str
    name: str | None = None
    description: str | None = None
    duration: float | None = None


def read_generate(text: str, file: str, families: dict[str, dict[str, tuple[int, int]]]) -> Generate | None:
    """The ``[generate]`` table of a scenario file, every field checked against ``families`` (kind -> size field
    -> (lowest, highest)) by file, line and field; None for an ordinary scenario file."""
    raw, r = _load_toml(text, file)
    if "generate" not in raw:
        return None
    for k in raw:
        if k not in GENERATE_KEYS and k in ("world", "radio", "start", "operator", "events", "criteria"):
            raise ScenarioError(file, _header_line(r, k) or r.line_of(k), k, "is generated with the world in a file "
                                "with [generate]; write the world out with `returnlink sim world FILE --out DIR` "
                                "and edit DIR/world.toml")
    r.known(raw, "", GENERATE_KEYS)
    r.finite(raw, "")
    gen = r.get(raw, "generate", "generate", dict)
    kind = r.get(gen, "kind", "generate.kind", str)
    if kind not in families:
        raise r.fail("generate.kind", f"unknown world family {kind!r} (one of {', '.join(families)})")
    r.known(gen, "generate", ("kind", *families[kind]))
    sizes = {}
    for name, (lo, hi) in families[kind].items():
        if name in gen:
            sizes[name] = r.get(gen, name, f"generate.{name}", int)
            if not lo <= sizes[name] <= hi:
                raise r.fail(f"generate.{name}", f"must be within {lo}..{hi}, got {sizes[name]}")
    vehicle, seed = _vehicle_and_seed(r, raw)
    duration = r.number(raw, "duration", "duration", None, lo=1.0, hi=36000.0)
    return Generate(file, _header_line(r, "generate"), kind, sizes, seed, vehicle,
                    r.get(raw, "name", "name", str, None), r.get(raw, "description", "description", str, None),
                    duration)


def scenario_source(name_or_path: str) -> tuple[str, str]:
    """(file name, text) of a built-in scenario by name, or of a TOML file by path."""
    if name_or_path in BUILTIN:
        text = resources.files("sim.scenarios").joinpath(f"{name_or_path}.toml").read_text(encoding="utf-8")
        return f"{name_or_path}.toml", text
    path = Path(name_or_path)
    if not path.is_file():
        raise ScenarioError(str(path), None, "", f"no such scenario file (built-in: {', '.join(BUILTIN)})")
    return str(path), path.read_text(encoding="utf-8")


def load(name_or_path: str) -> Scenario:
    """A built-in scenario by name, or a TOML file by path."""
    file, text = scenario_source(name_or_path)
    return parse(text, file)
