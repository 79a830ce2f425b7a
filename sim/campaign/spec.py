"""Campaign specs (TOML) -> the list of trials, checked whole before any trial runs.

```toml
scenarios = ["tunnel", "warehouse", "my_site.toml"]   # built-in names, gen:KIND, or files relative to this spec
vehicles = ["rover", "legged"]                        # default: each scenario's own robot
seeds = {from = 1, to = 20}                           # or a list; both ends included
policies = ["returnlink", "hold"]                     # default: ["returnlink"]
timeout_s = 300                                       # wall-clock seconds per trial
[params]                                              # a grid: every combination of these values
LNK_TIMEOUT = [2.0, 5.0]
[radio]                                               # the radio as an axis of the same grid (RADIO_AXES)
power_dbm = [-20.0, 0.0, 20.0]                        # the operator station's transmit power
exponent = [2.0, 2.5]
```

Trials are the cartesian product. A generated world (``gen:office``, or a file with ``[generate]``) is drawn
from each trial's seed, one world per seed, and the trial carries that world written out as a scenario file, so its
id hashes the world itself and a resumed campaign finds it again. A spec is written by hand and a campaign may run
for hours, so every mistake is found up front and named by file, line and field, like a scenario file's
(``SpecError``, exit code 2).
"""

from __future__ import annotations

import itertools
import math
import re
import sys
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from sim import registry
from sim.campaign.trial import RADIO_AXES, RADIO_PREFIX, Trial
from sim.registry import DEFAULT_POLICY, POLICY_NAMES, VEHICLES, flies
from sim.scenario import BUILTIN, ScenarioError
from sim.worlds.resolve import PREFIX, generator_text, parse, world_text
from vehicle.params import BY_NAME, ParamError, validate

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

FIELDS = ("scenarios", "vehicles", "seeds", "params", "radio", "policies", "timeout_s")
MAX_TRIALS = 1_000_000  # a typo such as seeds = {from = 1, to = 1e9} is refused before it fills a disk
DEFAULT_TIMEOUT_S = 600.0


class SpecError(ScenarioError):
    """A campaign spec that cannot run: ``file:line: field: what`` (same shape as a scenario file's errors)."""


@dataclass(frozen=True)
class Spec:
    file: str
    trials: tuple[Trial, ...]
    timeout_s: float


class _Lines:
    """Where a field of the spec was written: top-level ``key =``, or ``NAME =`` inside ``[params]``."""

    def __init__(self, file: str, text: str) -> None:
        self.file, self.lines = file, text.splitlines()

    def _find(self, pattern: str, start: int = 0, stop: int | None = None) -> int | None:
        rx = re.compile(pattern)
        for i in range(start, len(self.lines) if stop is None else stop):
            if rx.match(self.lines[i]):
                return i
        return None

    def line_of(self, field: str) -> int | None:
        top, _, sub = field.partition(".")
        top = re.sub(r"\[\d+\]$", "", top)
        first_table = self._find(r"^\s*\[")
        key = self._find(rf"^\s*{re.escape(top)}\s*=", 0, first_table)
        if not sub:
            if key is None:
                key = self._find(rf"^\s*\[\s*{re.escape(top)}\s*\]")
            return None if key is None else key + 1
        table = self._find(rf"^\s*\[\s*{re.escape(top)}\s*\]")
        if table is not None:
            name = re.sub(r"\[\d+\]$", "", sub)
            hit = self._find(rf"^\s*{re.escape(name)}\s*=", table + 1, self._find(r"^\s*\[", table + 1))
            return (hit if hit is not None else table) + 1
        return None if key is None else key + 1

    def fail(self, field: str, message: str) -> SpecError:
        return SpecError(self.file, self.line_of(field), field, message)


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _strings(r: _Lines, raw: dict, key: str, default: list[str] | None) -> list[str]:
    if key not in raw:
        if default is None:
            raise r.fail(key, "is required")
        return default
    v = raw[key]
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v:
        raise r.fail(key, f"must be a non-empty list of names, got {v!r}")
    for k, s in enumerate(v):
        if not isinstance(s, str):
            raise r.fail(f"{key}[{k}]", f"must be a name, got {s!r}")
    return v


def _scenario_text(r: _Lines, spec_dir: Path, name: str, fld: str) -> tuple[str, str, str]:
    """(name in the scenario, source as written, text) of a built-in scenario or a file next to the spec."""
    if name in BUILTIN:
        text = resources.files("sim.scenarios").joinpath(f"{name}.toml").read_text(encoding="utf-8")
        source = f"{name}.toml"
    elif name.startswith(PREFIX):
        try:
            text, source = generator_text(name), name
        except ScenarioError as e:
            raise r.fail(fld, f"scenario {name!r} is broken: {e}") from None
    else:
        path = Path(name) if Path(name).is_absolute() else spec_dir / name
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise r.fail(fld, f"cannot read scenario {name!r} ({path}): {e.__class__.__name__}: "
                              f"{getattr(e, 'strerror', None) or e} (built-in: {', '.join(BUILTIN)})") from None
        source = str(path)
    try:
        sc, _ = parse(text, source)
    except ScenarioError as e:
        raise r.fail(fld, f"scenario {name!r} is broken: {e}") from None
    return sc.name, source, text


def _seeds(r: _Lines, raw: dict) -> list[int]:
    v = raw.get("seeds")
    if isinstance(v, dict):
        extra = set(v) - {"from", "to"}
        if extra:
            raise r.fail("seeds", f"unknown key {sorted(extra)[0]!r} (a range is {{from = A, to = B}})")
        for k in ("from", "to"):
            if not isinstance(v.get(k), int) or isinstance(v.get(k), bool):
                raise r.fail("seeds", f"{{from, to}} needs whole numbers, {k} is {v.get(k)!r}")
        lo, hi = v["from"], v["to"]
        if lo > hi:
            raise r.fail("seeds", f"from {lo} is after to {hi}")
        seeds = list(range(lo, hi + 1)) if hi - lo < MAX_TRIALS else None
        if seeds is None:
            raise r.fail("seeds", f"{hi - lo + 1} seeds is more than {MAX_TRIALS}")
    elif isinstance(v, list) and v:
        for k, s in enumerate(v):
            if not isinstance(s, int) or isinstance(s, bool):
                raise r.fail(f"seeds[{k}]", f"must be a whole number, got {s!r}")
        seeds = list(dict.fromkeys(v))
    else:
        raise r.fail("seeds", f"must be a non-empty list or {{from = A, to = B}}, got {v!r}")
    for s in seeds:
        if not 0 <= s < 2**32:
            raise r.fail("seeds", f"seed {s} outside 0..{2**32 - 1}")
    return seeds


def _params(r: _Lines, raw: dict) -> dict[str, list[float]]:
    v = raw.get("params", {})
    if not isinstance(v, dict):
        raise r.fail("params", "must be a table: NAME = [values]")
    grid: dict[str, list[float]] = {}
    for name, values in v.items():
        fld = f"params.{name}"
        if name not in BY_NAME:
            raise r.fail(fld, f"unknown parameter (known: {', '.join(BY_NAME)})")
        values = values if isinstance(values, list) else [values]
        if not values:
            raise r.fail(fld, "needs at least one value")
        checked = []
        for x in values:
            if not _number(x):
                raise r.fail(fld, f"values must be finite numbers, got {x!r}")
            try:
                checked.append(validate(name, float(x)))
            except ParamError as e:
                raise r.fail(fld, str(e)) from None
        grid[name] = list(dict.fromkeys(checked))
    return grid


def _radio(r: _Lines, raw: dict) -> dict[str, list[float]]:
    """The ``[radio]`` grid: how strong the operator's radio is, swept like a vehicle parameter (a trial carries
    its values among its parameters as ``radio.NAME``, so they are hashed into its id and replayed with it)."""
    v = raw.get("radio", {})
    if not isinstance(v, dict):
        raise r.fail("radio", "must be a table: NAME = [values]")
    grid: dict[str, list[float]] = {}
    for name, values in v.items():
        fld = f"radio.{name}"
        if name not in RADIO_AXES:
            raise r.fail(fld, f"unknown radio setting (known: {', '.join(RADIO_AXES)})")
        lo, hi, _ = RADIO_AXES[name]
        values = values if isinstance(values, list) else [values]
        if not values:
            raise r.fail(fld, "needs at least one value")
        for x in values:
            if not _number(x) or not lo <= x <= hi:
                raise r.fail(fld, f"values must be numbers within {lo:g}..{hi:g}, got {x!r}")
        grid[RADIO_PREFIX + name] = list(dict.fromkeys(float(x) for x in values))
    return grid


def parse_spec(text: str, file: str = "<spec>", spec_dir: Path | None = None) -> Spec:
    """The trials of a spec, or SpecError naming the first mistake (the fields are checked in the order a reader
    meets them: the TOML, its fields, scenarios, vehicles, seeds, the grid, policies, their pairing, the timeout,
    the grid's size, then each generated world)."""
    r = _Lines(file, text)
    raw = _toml(r, text)
    spec_dir = spec_dir if spec_dir is not None else Path(file).resolve().parent
    names = _strings(r, raw, "scenarios", None)
    scenarios = [_scenario_text(r, spec_dir, n, f"scenarios[{k}]") for k, n in enumerate(names)]
    vehicles = _vehicles(r, raw)
    seeds = _seeds(r, raw) if "seeds" in raw else None
    grid = {**_params(r, raw), **_radio(r, raw)}
    policies = _policies(r, raw)
    _check_pairing(r, policies, vehicles or [parse(text_, source)[0].vehicle for _, source, text_ in scenarios],
                   vehicles or [])
    timeout = raw.get("timeout_s", DEFAULT_TIMEOUT_S)
    if not _number(timeout) or timeout <= 0:
        raise r.fail("timeout_s", f"must be a positive number of wall-clock seconds, got {timeout!r}")
    combos = [tuple(zip(grid, values, strict=True)) for values in itertools.product(*grid.values())]
    n = len(scenarios) * len(vehicles or [None]) * len(seeds or [None]) * len(combos) * len(policies)
    if n > MAX_TRIALS:
        raise r.fail("scenarios", f"the grid has {n} trials, more than {MAX_TRIALS}")
    trials: dict[str, Trial] = {}
    for k, scenario in enumerate(scenarios):
        for t in _scenario_trials(r, k, scenario, vehicles, seeds, combos, policies):
            trials.setdefault(t.id, t)
    return Spec(file, tuple(trials.values()), float(timeout))


def _toml(r: _Lines, text: str) -> dict:
    """The spec's TOML table, its fields all known; a TOML error names its line."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        m = re.search(r"line (\d+)", str(e))
        line = int(m.group(1)) if m else (max(1, len(r.lines)) if "end of document" in str(e) else None)
        raise SpecError(r.file, line, "", f"not valid TOML: {e}") from None
    for k in raw:
        if k not in FIELDS:
            raise r.fail(k, f"unknown field (expected one of {', '.join(FIELDS)})")
    return raw


def _vehicles(r: _Lines, raw: dict) -> list[str] | None:
    """The listed vehicles, or None for each scenario's own robot."""
    if "vehicles" not in raw:
        return None
    vehicles = _strings(r, raw, "vehicles", [])
    for k, veh in enumerate(vehicles):
        if veh not in VEHICLES:
            raise r.fail(f"vehicles[{k}]", f"must be one of {', '.join(VEHICLES)}, got {veh!r}")
    return vehicles


def _policies(r: _Lines, raw: dict) -> list[str]:
    policies = _strings(r, raw, "policies", [DEFAULT_POLICY])
    for k, p in enumerate(policies):
        if p not in POLICY_NAMES:
            raise r.fail(f"policies[{k}]", f"unknown policy {p!r} (known: {', '.join(POLICY_NAMES)})")
    return policies


def _check_pairing(r: _Lines, policies: list[str], listed: list[str], vehicles: list[str]) -> None:
    """The grid pairs each policy with the vehicles that can fly it (the ArduPilot firmware's failsafes with that
    firmware, PX4's with PX4, the native policies with the native robots), so one spec compares them all; a policy
    no ``listed`` vehicle (the spec's, else the scenarios' own) flies is an error, as is a vehicle of the spec's
    ``vehicles`` no listed policy suits."""
    for k, p in enumerate(policies):
        if not any(flies(p, veh) for veh in listed):
            raise r.fail(f"policies[{k}]", f"policy {p!r} needs {registry.spec_need(p)} in vehicles")
    for k, veh in enumerate(vehicles):
        if not any(flies(p, veh) for p in policies):
            raise r.fail(f"vehicles[{k}]", f"no listed policy can be flown by vehicle {veh!r}")


def _scenario_trials(r: _Lines, k: int, scenario: tuple[str, str, str], vehicles: list[str] | None,
                     seeds: list[int] | None, combos: list[tuple], policies: list[str]):
    """The trials of the ``k``-th scenario, in grid order: each vehicle, seed, parameter combination and policy the
    vehicle flies. A generated world is drawn once per seed, and the trial carries it written out."""
    name, source, text_ = scenario
    own, generated = parse(text_, source)
    flown = {}  # seed -> the scenario text it flies
    for veh in vehicles or [own.vehicle]:
        for seed in seeds or [own.seed]:
            if seed not in flown:
                try:
                    flown[seed] = text_ if generated is None else world_text(text_, source, seed)
                except ScenarioError as e:
                    raise r.fail(f"scenarios[{k}]", f"scenario {name!r}, seed {seed}: {e}") from None
            for combo in combos:
                for policy in policies:
                    if flies(policy, veh):
                        yield Trial(name, source, flown[seed], veh, seed, tuple(sorted(combo)), policy)


def load_spec(path: str | Path) -> Spec:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise SpecError(str(p), None, "", f"cannot read the spec: {getattr(e, 'strerror', None) or e}") from None
    return parse_spec(text, str(p), p.resolve().parent)
