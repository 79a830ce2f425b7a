"""Generated worlds (docs/architecture.md §7.1): families of places drawn from a seed, usable wherever a scenario is.

``gen:office``, ``gen:mine`` and ``gen:culvert`` name a family; the run's seed picks the world. Each family is a
module with a pure ``generate(rng, **size) -> Scenario``, its size fields (``SIZES``: name -> (lowest, highest))
and its validity check (``check_world``, the same for every family: ``sim.worlds.check``). ``generate`` here
draws from sub-seeds of the seed (a ``numpy.random.SeedSequence`` spawned per attempt) until a draw is valid,
so the same seed always gives the same world, and a world that does not mean something (an undrivable route, a
link that never dies) is never handed out. A size field not given is drawn from its range with the world.

Names (``gen:KIND``, files with ``[generate]``) are resolved by ``sim.worlds.resolve``; ``sim.worlds.toml_out``
writes a world as an ordinary scenario file and ``sim.worlds.render`` draws it (`returnlink sim world`).
"""

from __future__ import annotations

from dataclasses import replace
from types import ModuleType

import numpy as np

from sim.worlds import culvert, mine, office

FAMILIES: dict[str, ModuleType] = {"office": office, "mine": mine, "culvert": culvert}
PREFIX = "gen:"
REDRAWS = 50  # draws a seed may take before the family gives up on it


class WorldError(ValueError):
    """No valid world within the redraw budget (or a bad family or size): the message says which and why."""


def sizes(kind: str) -> dict[str, tuple[int, int]]:
    """The size fields of family ``kind`` and their ranges."""
    return dict(FAMILIES[kind].SIZES)


def generate(kind: str, seed: int, size_overrides: dict[str, int] | None = None):
    """``(scenario, redraws)``: the first valid world of family ``kind`` drawn from ``seed``'s sub-seeds, and
    how many draws before it were thrown away. WorldError after REDRAWS invalid draws."""
    if kind not in FAMILIES:
        raise WorldError(f"unknown world family {kind!r} (one of {', '.join(FAMILIES)})")
    family, given = FAMILIES[kind], dict(size_overrides or {})
    for name, value in given.items():
        if name not in family.SIZES:
            raise WorldError(f"family {kind} has no size {name!r} (its sizes: {', '.join(family.SIZES)})")
        lo, hi = family.SIZES[name]
        if not lo <= value <= hi:
            raise WorldError(f"{kind} {name} must be within {lo}..{hi}, got {value}")
    last = ""
    for attempt, child in enumerate(np.random.SeedSequence(seed).spawn(REDRAWS)):
        rng = np.random.default_rng(child)
        size = {name: given.get(name, int(rng.integers(lo, hi + 1))) for name, (lo, hi) in family.SIZES.items()}
        sc = family.generate(rng, **size)
        verdict = family.check_world(sc)
        if verdict.ok:
            described = f"{sc.description} Seed {seed}, {attempt} draw{'s' if attempt != 1 else ''} redrawn; " + \
                ", ".join(f"{k} = {v}" for k, v in size.items()) + "."
            return replace(sc, seed=seed, description=described), attempt
        last = "; ".join(verdict.problems)
    raise WorldError(f"no valid {kind} world from seed {seed} in {REDRAWS} draws (the last: {last})")
