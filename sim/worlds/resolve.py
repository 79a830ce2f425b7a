"""Any scenario name to a Scenario, generated worlds included: what `sim run`, `sim serve`, `sim world` and a
campaign spec resolve names with.

``gen:KIND`` stands for the file ``[generate] kind = "KIND"`` (every size drawn with the world); a file with
``[generate]`` is read and range-checked by ``sim.scenario.read_generate``; anything else is an ordinary
scenario (``sim.scenario``). This module sits above both ``sim.scenario`` and the families, so neither imports
the other's caller (docs/architecture.md §2: no import circles).
"""

from __future__ import annotations

from dataclasses import replace

from sim import scenario, worlds
from sim.scenario import Scenario, ScenarioError

PREFIX = worlds.PREFIX


def generator_text(name: str) -> str:
    """The scenario file that ``gen:KIND`` stands for; ScenarioError (no line: there is no file) for an unknown
    family."""
    kind = name[len(PREFIX):]
    if kind not in worlds.FAMILIES:
        raise ScenarioError(name, None, "", f"unknown world family {kind!r} (gen:KIND with KIND one of "
                                            f"{', '.join(worlds.FAMILIES)})")
    return f'name = "{name}"\n\n[generate]\nkind = "{kind}"\n'


def source(name_or_path: str) -> tuple[str, str]:
    """(file name, text) of a built-in scenario, a ``gen:KIND`` family or a TOML file by path."""
    if name_or_path.startswith(PREFIX):
        return name_or_path, generator_text(name_or_path)
    return scenario.scenario_source(name_or_path)


def parse(text: str, file: str, seed: int | None = None) -> tuple[Scenario, int | None]:
    """The scenario of ``text`` and how many draws its world took beyond the first (None: not generated). A
    generated world is drawn from ``seed`` (default: the file's own), with the file's name, description, duration
    and vehicle on top where it gives them; no valid draw is a ScenarioError at the [generate] table."""
    gen = scenario.read_generate(text, file, {k: worlds.sizes(k) for k in worlds.FAMILIES})
    if gen is None:
        return scenario.parse(text, file), None
    try:
        sc, redraws = worlds.generate(gen.kind, gen.seed if seed is None else seed, gen.sizes)
    except worlds.WorldError as e:
        raise ScenarioError(file, gen.line, "generate", str(e)) from None
    own = {"name": gen.name, "description": gen.description, "duration": gen.duration}
    return replace(sc, file=file, vehicle=gen.vehicle, **{k: v for k, v in own.items() if v is not None}), redraws


def load(name_or_path: str, seed: int | None = None) -> tuple[Scenario, int | None]:
    """``parse`` of a built-in scenario, a ``gen:KIND`` family or a file by path."""
    file, text = source(name_or_path)
    return parse(text, file, seed)


def world_text(text: str, file: str, seed: int) -> str:
    """The scenario text a run with ``seed`` flies: ``text`` itself, or, for a generated world, the world drawn
    for ``seed`` written out as an ordinary scenario file (what a campaign's trial hashes, stores and replays)."""
    sc, redraws = parse(text, file, seed)
    if redraws is None:
        return text
    from sim.worlds.toml_out import to_toml

    return to_toml(sc)
