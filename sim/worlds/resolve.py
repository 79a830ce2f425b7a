"""Any scenario name to a Scenario, generated worlds included: what `sim run`, `sim serve`, `sim world` and a
campaign spec resolve names with.

``gen:KIND`` stands for the file ``[generate] kind = "KIND"`` (every size drawn with the world); a file with
``[generate]`` is read and range-checked by ``sim.scenario.read_generate``; anything else is an ordinary
scenario (``sim.scenario``). This module sits above both ``sim.scenario`` and the families, so neither imports
the other's caller (docs/architecture.md §2: no import circles).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from sim import scenario, worlds
from sim.scenario import Scenario, ScenarioError
from sim.worlds.map_routes import RouteError, draw

PREFIX = worlds.PREFIX
MAP_PREFIX = "map:"  # map:PATH.yaml: a world made from a map_server map (docs/architecture.md §7.2)


def generator_text(name: str) -> str:
    """The scenario file that ``gen:KIND`` stands for; ScenarioError (no line: there is no file) for an unknown
    family."""
    kind = name[len(PREFIX):]
    if kind not in worlds.FAMILIES:
        raise ScenarioError(name, None, "", f"unknown world family {kind!r} (gen:KIND with KIND one of "
                                            f"{', '.join(worlds.FAMILIES)})")
    return f'name = "{name}"\n\n[generate]\nkind = "{kind}"\n'


def _toml(v) -> str:
    return json.dumps(v) if isinstance(v, str) else repr(float(v)) if not isinstance(v, bool) else str(v).lower()


def map_text(name: str, station: tuple[float, float] | None, radio: dict[str, float] | None = None) -> str:
    """The scenario file that ``map:PATH.yaml`` with ``--station X,Y`` stands for (and a ``--radio`` file's
    table); ScenarioError naming the field when the station is missing."""
    path = Path(name[len(MAP_PREFIX):])
    if station is None:
        raise ScenarioError(name, None, "station", "a map world needs its ground station's place: --station X,Y "
                                                   "(map frame, metres: x east, y north), or a scenario file whose "
                                                   "[map] table has station = [X, Y]")
    lines = [f"name = {json.dumps('map:' + path.stem)}", "", "[map]", f"file = {json.dumps(str(path.resolve()))}",
             f"station = [{float(station[0])!r}, {float(station[1])!r}]"]
    if radio:
        lines += ["", "[radio]"] + [f"{k} = {_toml(v)}" for k, v in radio.items()]
    return "\n".join(lines) + "\n"


def source(name_or_path: str, station: tuple[float, float] | None = None,
           radio: dict[str, float] | None = None) -> tuple[str, str]:
    """(file name, text) of a built-in scenario, a ``gen:KIND`` family, a ``map:PATH.yaml`` map (with its
    station) or a TOML file by path."""
    if name_or_path.startswith(PREFIX):
        return name_or_path, generator_text(name_or_path)
    if name_or_path.startswith(MAP_PREFIX):
        return name_or_path, map_text(name_or_path, station, radio)
    return scenario.scenario_source(name_or_path)


def _map_world(mw: scenario.MapWorld, file: str, seed: int | None) -> tuple[Scenario, int]:
    try:
        sc, redraws = draw(mw.table.site, mw.table.station, mw.radio, mw.seed if seed is None else seed, mw.name,
                           mw.description or "")
    except RouteError as e:
        raise ScenarioError(file, mw.table.line, "map", f"{mw.table.site.file}: {e}") from None
    own = {"duration": mw.duration}
    return replace(sc, file=file, vehicle=mw.vehicle, **{k: v for k, v in own.items() if v is not None}), redraws


def parse(text: str, file: str, seed: int | None = None) -> tuple[Scenario, int | None]:
    """The scenario of ``text`` and how many draws its world took beyond the first (None: not generated). A
    generated world (a family's, or a route on a map) is drawn from ``seed`` (default: the file's own), with the
    file's name, description, duration and vehicle on top where it gives them; no valid draw is a ScenarioError
    at the [generate] (or [map]) table."""
    mw = scenario.read_map_world(text, file)
    if mw is not None:
        return _map_world(mw, file, seed)
    gen = scenario.read_generate(text, file, {k: worlds.sizes(k) for k in worlds.FAMILIES})
    if gen is None:
        return scenario.parse(text, file), None
    try:
        sc, redraws = worlds.generate(gen.kind, gen.seed if seed is None else seed, gen.sizes)
    except worlds.WorldError as e:
        raise ScenarioError(file, gen.line, "generate", str(e)) from None
    own = {"name": gen.name, "description": gen.description, "duration": gen.duration}
    return replace(sc, file=file, vehicle=gen.vehicle, **{k: v for k, v in own.items() if v is not None}), redraws


def load(name_or_path: str, seed: int | None = None, station: tuple[float, float] | None = None,
         radio: tuple[dict[str, float], dict[str, float]] | None = None) -> tuple[Scenario, int | None]:
    """``parse`` of a built-in scenario, a ``gen:KIND`` family, a ``map:PATH.yaml`` map or a file by path;
    ``radio`` (a ``--radio`` file's model fields and map loss) on top of the scenario's own."""
    model, loss = radio or ({}, {})
    file, text = source(name_or_path, station, {**model, **loss})
    if name_or_path.startswith(MAP_PREFIX) or not (model or loss):
        return parse(text, file, seed)
    mw = scenario.read_map_world(text, file)
    if mw is not None:  # the route depends on the radio: drawn with it
        mw = replace(mw, radio=replace(mw.radio, **model), table=replace(mw.table, site=replace(mw.table.site,
                                                                                                   **loss)))
        return _map_world(mw, file, seed)
    sc, redraws = parse(text, file, seed)
    return replace(sc, radio=replace(sc.radio, **model),
                   site=replace(sc.site, **loss) if sc.site is not None else None), redraws


def world_text(text: str, file: str, seed: int) -> str:
    """The scenario text a run with ``seed`` flies: ``text`` itself, or, for a generated world, the world drawn
    for ``seed`` written out as an ordinary scenario file (what a campaign's trial hashes, stores and replays)."""
    sc, redraws = parse(text, file, seed)
    if redraws is None:
        return text
    from sim.worlds.toml_out import to_toml

    return to_toml(sc)
