"""The parameter table of docs/architecture.md §5 and the .parm text format (MAVProxy/ArduPilot), shared by both ends.

The names, defaults, ranges and meanings are part of the interface contract: the vehicle enforces them, and a
ground station, a scenario file or a campaign spec checks a value against the same table before it sends or runs
anything. The vehicle keeps the current values and its files (``vehicle/params.py``); this module has no state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: float
    lo: float
    hi: float
    units: str
    meaning: str
    integer: bool = False


SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("LNK_TIMEOUT", 3.0, 0.5, 120.0, "s", "owner silent this long -> COMMS_LOST"),
    ParamSpec("LNK_REGAIN_S", 1.0, 0.0, 10.0, "s",
              "owner heard again this long, delivering at least 80 % of its packets over it -> LINK_REGAINED"),
    ParamSpec("LNK_GOOD_S", 1.5, 0.1, 10.0, "s", "a crumb is link-good if the owner was heard within this"),
    ParamSpec("RTL_MAX_DISP", 50.0, 1.0, 10000.0, "m", "max displacement of one return block"),
    ParamSpec("RTL_MAX_TIME", 300.0, 0.0, 3600.0, "s", "a return block gives up after this (0 = no limit)"),
    ParamSpec("RTL_SPEED", 0.0, 0.0, 5.0, "m/s", "return speed; 0 = the speed used outbound"),
    ParamSpec("RTL_TARGET", 0, 0, 2, "", "LINK / ORIGIN / HEADING", integer=True),
    ParamSpec("RTL_REGAIN_ACT", 0, 0, 1, "", "on link regained: 0 halt and hold, 1 continue to target", integer=True),
    ParamSpec("RTL_REARM", 1, 0, 1, "", "reschedule the return plan behind every fresh operator lease", integer=True),
    ParamSpec("RTL_ARRIVE_R", 1.0, 0.1, 10.0, "m", "arrival radius"),
    ParamSpec("RTL_CUT_CLR", 0.9, 0.0, 5.0, "m",
              "a return cuts a corner only through space its range sensor saw free this far from its centre, "
              "and keeps this far from what it saw occupied where it can (half-width plus margin; 0 = retrace "
              "the crumbs)"),
    ParamSpec("TRL_SPACING", 0.5, 0.05, 10.0, "m", "minimum distance between recorded crumbs"),
    ParamSpec("TRL_TOL", 0.25, 0.01, 5.0, "m", "simplification tolerance (degrades upward only when memory is full)"),
    ParamSpec("TRL_LOOP_D", 1.0, 0.1, 10.0, "m", "trail segments closer than this close a loop"),
    ParamSpec("TRL_MAX_PTS", 2000, 50, 100000, "", "memory bound of the trail", integer=True),
    ParamSpec("LEASE_AUTOGRANT", 1, 0, 1, "", "plain clients get the root implicitly", integer=True),
    ParamSpec("LEASE_STALE_TAKE", 1, 0, 1, "", "a silent owner may be taken over", integer=True),
    ParamSpec("LNK_MIN_Q", 0.25, 0.0, 0.9, "",
              "owner's packet delivery below this for LNK_TIMEOUT also counts as lost (0 = silence only)"),
    ParamSpec("LNK_MAP_CELL", 2.0, 0.5, 20.0, "m", "cell size of the link map (a new size starts a new map)"),
    ParamSpec("LNK_MAP_CELLS", 1024, 16, 65536, "", "memory bound of the link map (far cells are dropped first)",
              integer=True),
    ParamSpec("LNK_MAP_OBS", 3, 1, 1000, "", "observations (0.5 s looks) before a cell can count as reliable",
              integer=True),
    ParamSpec("LNK_MAP_MARGIN", 0.3, 0.0, 0.9, "",
              "a reliable cell's delivery lower bound exceeds LNK_MIN_Q by this, and meets the regain's 80 % "
              "whatever this is"),
    ParamSpec("LNK_MAP_SEEK", 1000.0, 0.0, 1000.0, "m",
              "at the map's place with the link still down, go on back along the trail this far, at "
              "RTL_APPROACH_SPD and within the block's displacement and time (0 = stay)"),
    ParamSpec("LNK_HOLD_S", 1.0, 0.0, 10.0, "s",
              "companion: the owner driving the autopilot with setpoints in GUIDED silent this long (and longer "
              "than its longest gap between packets of the last 5 s) -> the drive is stopped (0 = never)"),
    ParamSpec("RTL_BODY_R", 0.0, 0.0, 5.0, "m",
              "the robot's footprint radius: a return keeps its body a few cm off what the range sensor sees "
              "now, whatever the estimate's error (0 = unknown, not kept)"),
    ParamSpec("RTL_APPROACH_SPD", 1.0, 0.0, 5.0, "m/s",
              "while the owner is heard well again during a return (its delivery since the contact began at the "
              "regain's share) and from the regain window's third such packet to the block's end, and while seeking "
              "past the link map's place, the return drives no faster than this, so the regain window and the braking "
              "end close to where the link came back (0 = no slowing)"),
)
BY_NAME = {s.name: s for s in SPECS}


def default(name: str) -> float:
    """The contract default of ``name``: every feature's Config takes its defaults from here, so the table above
    is the one place a default is written (``params/returnlink.parm`` is kept in step with it by a test)."""
    return BY_NAME[name].default


class ParamError(ValueError):
    pass


def validate(name: str, value: float) -> float:
    """The value to store, or ParamError saying why not (unknown name, not finite, out of range, not whole)."""
    spec = BY_NAME.get(name)
    if spec is None:
        raise ParamError(f"{name}: unknown parameter")
    if not math.isfinite(value):
        raise ParamError(f"{name}: {value} is not a number")
    if not spec.lo <= value <= spec.hi:
        raise ParamError(f"{name}: {value:g} outside {spec.lo:g}..{spec.hi:g}")
    if spec.integer:
        if value != int(value):
            raise ParamError(f"{name}: {value:g} must be a whole number")
        return float(int(value))
    return float(value)


class BadLine(ValueError):
    """A .parm line that is not ``NAME VALUE`` with a valid value: its line number and what is wrong."""

    def __init__(self, line: int, what: str) -> None:
        super().__init__(what)
        self.line, self.what = line, what


def parse_lines(text: str) -> dict[str, float]:
    """The values of a .parm text, or BadLine(line, what) at the first line that is not ``NAME VALUE``."""
    out: dict[str, float] = {}
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").split()
        if len(parts) != 2:
            raise BadLine(n, f"expected 'NAME VALUE', got {raw.strip()!r}")
        try:
            value = float(parts[1])
        except ValueError:
            raise BadLine(n, f"{parts[1]!r} is not a number") from None
        try:
            out[parts[0]] = validate(parts[0], value)
        except ParamError as e:
            raise BadLine(n, str(e)) from None
    return out


def parse_parm(text: str, source: str = "<parm>") -> dict[str, float]:
    """MAVProxy/ArduPilot .parm: ``NAME VALUE`` (or ``NAME,VALUE``) per line, ``#`` comments."""
    try:
        return parse_lines(text)
    except BadLine as e:
        raise ParamError(f"{source}:{e.line}: {e.what}") from None


def format_parm(values: dict[str, float]) -> str:
    lines = ["# returnlink parameters (MAVProxy/ArduPilot .parm format)"]
    for s in SPECS:
        if s.name in values:
            v = values[s.name]
            lines.append(f"{s.name:<16} {int(v) if s.integer else f'{v:g}'}")
    return "\n".join(lines) + "\n"
