"""Whether two runs of one trial are the same run: one comparator of metrics.json, for every plant.

A run of returnlink's own vehicle is deterministic (same scenario and seed, same bytes), so its metrics must repeat
exactly (``EXACT``); a real autopilot repeats only within its own determinism, which its plant states as a
``Repeatability`` (``sim.firmware.metrics.REPEATABILITY``: how far each figure may move). ``differing`` names
the metrics that differ beyond what the plant allows; `sim run --replay` and the repeatability tests read it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

# (the figure's own key, the metric it belongs to) -> how far it may move; a figure nested in a table or a list of
# records (a block's ``start_s``, a mode's ``t``) is asked by its own key, with the metric around it
Tolerance = Callable[[str, str], float]


@dataclass(frozen=True)
class Repeatability:
    """How far two runs of one trial may differ and still count as the same run: ``tolerance`` per figure (0:
    exactly), and the metrics never compared (``ignored``: the wall-clock real-time factor, and for an autopilot
    the verdict's wording, which quotes counts). ``exact`` says which of the two a replay may promise."""

    tolerance: Tolerance = lambda key, metric: 0.0
    ignored: frozenset[str] = frozenset({"real_time_factor"})
    exact: bool = True


EXACT = Repeatability()


def differing(a: dict, b: dict, within: Repeatability = EXACT) -> list[str]:
    """The names of the metrics that differ between ``a`` and ``b`` beyond ``within``, sorted; [] means the same
    run. A metric missing on one side differs from any value on the other but None."""
    return [k for k in sorted(set(a) | set(b))
            if k not in within.ignored and not _same(k, k, a.get(k), b.get(k), within.tolerance)]


def _same(key: str, metric: str, x, y, tolerance: Tolerance) -> bool:
    """Flags, names and missing figures exactly; numbers within the figure's tolerance (two NaN are the same
    figure); tables key by key and lists element by element."""
    if _exact(x) or _exact(y):
        return x == y
    if isinstance(x, (int, float)) and isinstance(y, (int, float)):
        return _same_number(x, y, tolerance(key, metric))
    if isinstance(x, dict) and isinstance(y, dict):
        return x.keys() == y.keys() and all(_same(k, metric, x[k], y[k], tolerance) for k in x)
    if isinstance(x, list) and isinstance(y, list):
        return len(x) == len(y) and all(_same(key, metric, p, q, tolerance) for p, q in zip(x, y, strict=True))
    return x == y


def _same_number(x: float, y: float, allowed: float) -> bool:
    """Equal (allowed 0), or within ``allowed``; two NaN are the same missing figure."""
    if math.isnan(x) and math.isnan(y):
        return True
    return x == y if allowed == 0 else abs(x - y) <= allowed + 1e-9


def _exact(x) -> bool:
    """A value compared exactly: a flag, a name or a missing figure."""
    return isinstance(x, (bool, str)) or x is None
