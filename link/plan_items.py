"""The kinds of return-plan item and the range of every one of their fields: one table, checked where a plan
enters (the vehicle's mission protocol and RETURN_TO_LINK command, the ground station's WPL files and ``--spec``).

Why one table in ``link/``: a plan refused by the vehicle after the ground station accepted it (or the reverse)
is a plan the operator believes in and does not have. A plan item whose field is out of range must be refused
when it arrives, while the link is up and someone can fix it, never discovered when the return starts, which is
exactly when the link is gone. Both ends import this module; neither imports the other.

NaN and infinity are explicit: infinity is never a valid field. NaN is MAVLink's "unset" for a float parameter:
a field with a ``nan`` value takes that value (for example -1 = use the parameter); a field without one refuses
NaN. Fields a kind does not use accept any finite number or NaN and are ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from link import dialect

mav = dialect.load()

# MAV_CMD numbers of the items a return plan may hold (RETURN_TO_LINK and LEASE_BOUNDARY are returnlink's own)
NAV_WAYPOINT = mav.MAV_CMD_NAV_WAYPOINT
NAV_LOITER_TIME = mav.MAV_CMD_NAV_LOITER_TIME
NAV_RETURN_TO_LAUNCH = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
NAV_RETURN_TO_LINK = mav.MAV_CMD_NAV_RETURN_TO_LINK
LEASE_BOUNDARY = mav.MAV_CMD_LEASE_BOUNDARY

# MAV_FRAME groups: how MISSION_ITEM_INT's integer x/y are scaled in each
GLOBAL_FRAMES = (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_INT,
                 mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT,
                 mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)  # x/y are lat/lon (degE7 in MISSION_ITEM_INT)
LOCAL_FRAMES = (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED)  # x/y are metres * 1e4
MISSION_FRAME = mav.MAV_FRAME_MISSION  # x/y are the raw numbers of a command without a position
KNOWN_FRAMES = tuple(sorted(v for v in mav.enums["MAV_FRAME"] if v != mav.MAV_FRAME_ENUM_END))

# MAV_MISSION_RESULT codes a refused item is answered with
MISSION_UNSUPPORTED_FRAME = mav.MAV_MISSION_UNSUPPORTED_FRAME
MISSION_UNSUPPORTED = mav.MAV_MISSION_UNSUPPORTED
MISSION_INVALID = mav.MAV_MISSION_INVALID
MISSION_INVALID_PARAM = {1: mav.MAV_MISSION_INVALID_PARAM1, 2: mav.MAV_MISSION_INVALID_PARAM2,
                         3: mav.MAV_MISSION_INVALID_PARAM3, 4: mav.MAV_MISSION_INVALID_PARAM4,
                         5: mav.MAV_MISSION_INVALID_PARAM5_X, 6: mav.MAV_MISSION_INVALID_PARAM6_Y,
                         7: mav.MAV_MISSION_INVALID_PARAM7}

MAX_DISPLACEMENT = 10000.0  # m: the largest displacement budget, and how far a local waypoint may be
MAX_RETURN_SPEED = 5.0  # m/s
MAX_LOITER = 3600.0  # s


def position_scale(frame: int) -> float:
    """What MISSION_ITEM_INT (and a QGC WPL file, after scaling) multiplies x/y by in this frame."""
    return 1e7 if frame in GLOBAL_FRAMES else (1e4 if frame in LOCAL_FRAMES else 1.0)


@dataclass(frozen=True)
class FieldRange:
    """One field: its meaning, its range, whether it must be whole, values allowed outside the range, and what
    NaN stands for (None: NaN is refused)."""

    label: str
    lo: float = -math.inf
    hi: float = math.inf
    integer: bool = False
    special: tuple[float, ...] = ()
    nan: float | None = None
    used: bool = True

    def check(self, value: float) -> str | None:
        """Why ``value`` is not acceptable, or None."""
        if math.isnan(value):
            return None if self.nan is not None or not self.used else "NaN is not allowed"
        if math.isinf(value):
            return f"{value} is not a finite number"
        if not self.used or value in self.special:
            return None
        if not self.lo <= value <= self.hi:
            extra = "".join(f" or {s:g}" for s in self.special)
            return f"{value:g} outside {self.lo:g}..{self.hi:g}{extra}"
        if self.integer and value != int(value):
            return f"{value:g} must be a whole number"
        return None

    def value(self, raw: float) -> float:
        """The value a checked field stands for (NaN replaced by its meaning)."""
        if math.isnan(raw):
            return self.nan if self.nan is not None else 0.0
        return float(raw)


UNUSED = FieldRange("unused", used=False)


def command_name(command: int) -> str:
    """A plan command's name as plans, logs and messages write it: the dialect's MAV_CMD name without its
    ``MAV_CMD_`` / ``NAV_`` prefix (``RETURN_TO_LINK``, ``LOITER_TIME``, ``LEASE_BOUNDARY``...)."""
    return mav.enums["MAV_CMD"][command].name.removeprefix("MAV_CMD_").removeprefix("NAV_")


@dataclass(frozen=True)
class Kind:
    """One item kind: its MAV_CMD, its seven fields (param1..4, x, y, z), and whether x/y are a position."""

    command: int
    fields: tuple[FieldRange, ...]
    position: bool = False

    @property
    def name(self) -> str:
        return command_name(self.command)

    def field(self, index: int, frame: int) -> FieldRange:
        """Field 1..7; a position's x/y range depends on the frame (degrees or metres)."""
        if self.position and index in (5, 6):
            if frame in GLOBAL_FRAMES:
                return FieldRange("latitude", -90.0, 90.0) if index == 5 else FieldRange("longitude", -180.0, 180.0)
            return FieldRange("north" if index == 5 else "east", -MAX_DISPLACEMENT, MAX_DISPLACEMENT)
        return self.fields[index - 1]


KINDS: dict[int, Kind] = {k.command: k for k in (
    Kind(NAV_RETURN_TO_LINK, (
        FieldRange("max displacement", 0.0, MAX_DISPLACEMENT, nan=0.0),  # 0 = RTL_MAX_DISP
        FieldRange("speed", 0.0, MAX_RETURN_SPEED, nan=0.0),  # 0 = RTL_SPEED
        FieldRange("target", 0, 2, integer=True, special=(-1.0,), nan=-1.0),  # RTL_TARGET; -1 = the parameter
        FieldRange("on regain", 0, 1, integer=True, special=(-1.0,), nan=-1.0),  # -1 = RTL_REGAIN_ACT
        FieldRange("heading", -360.0, 360.0, nan=0.0),  # degrees, for target HEADING
        UNUSED, UNUSED)),
    Kind(LEASE_BOUNDARY, (UNUSED,) * 7),
    Kind(NAV_LOITER_TIME, (
        FieldRange("time", 0.0, MAX_LOITER),  # s; NaN refused: how long to hold is the point of the item
        UNUSED, UNUSED, UNUSED, UNUSED, UNUSED, UNUSED)),  # heading, radius, xtrack, position: a rover holds in place
    Kind(NAV_RETURN_TO_LAUNCH, (UNUSED,) * 7),
    Kind(NAV_WAYPOINT, (
        FieldRange("hold", 0.0, MAX_LOITER, nan=0.0), FieldRange("acceptance radius", 0.0, 1000.0, nan=0.0),
        UNUSED, UNUSED, UNUSED, UNUSED, UNUSED), position=True),
)}
NAMES = {k.command: k.name for k in KINDS.values()}  # the plan commands by MAV_CMD number: the one home of their names
COMMANDS = {name: command for command, name in NAMES.items()}  # ... and by name
PARAM_NAMES = ("param1", "param2", "param3", "param4", "x", "y", "z")


@dataclass(frozen=True)
class ItemFault:
    """Why one item is refused: the field (1..7, or 0 for the item as a whole), the MAV_MISSION_RESULT to answer
    with, and a message naming both."""

    field: int
    result: int
    message: str


class ItemError(ValueError):
    """A plan item refused where it entered; carries the fault for the MISSION_ACK."""

    def __init__(self, seq: int, fault: ItemFault) -> None:
        self.seq, self.fault = seq, fault
        super().__init__(f"item {seq}: {fault.message}")


def check_fields(command: int, frame: int, values: tuple[float, ...]) -> ItemFault | None:
    """Check a plan item's kind, frame and seven fields (x/y in degrees or metres, already unscaled)."""
    kind = KINDS.get(command)
    if kind is None:
        return ItemFault(0, MISSION_UNSUPPORTED, f"command {command} is not supported in a return plan "
                                                 f"(one of {', '.join(f'{n} {c}' for c, n in NAMES.items())})")
    if frame not in KNOWN_FRAMES or (kind.position and frame not in GLOBAL_FRAMES + LOCAL_FRAMES):
        return ItemFault(0, MISSION_UNSUPPORTED_FRAME, f"{kind.name}: frame {frame} is not supported")
    for i, v in enumerate(values, 1):
        f = kind.field(i, frame)
        why = f.check(float(v))
        if why is not None:
            return ItemFault(i, MISSION_INVALID_PARAM[i], f"{kind.name} {PARAM_NAMES[i - 1]} ({f.label}): {why}")
    return None


def check_item(command: int, frame: int, params: tuple[float, float, float, float], x: int | float,
               y: int | float, z: float, current: int = 0, autocontinue: int = 1) -> ItemFault | None:
    """Check a mission item in its MISSION_ITEM_INT form (x/y scaled by the frame)."""
    if current not in (0, 1) or autocontinue not in (0, 1):
        return ItemFault(0, MISSION_INVALID, f"current {current} / autocontinue {autocontinue}: must be 0 or 1")
    scale = position_scale(frame)
    return check_fields(command, frame, (*params, x / scale, y / scale, z))


def values(command: int, frame: int, raw: tuple[float, ...]) -> tuple[float, ...]:
    """The seven checked fields with NaN replaced by what it stands for."""
    kind = KINDS[command]
    return tuple(kind.field(i, frame).value(v) for i, v in enumerate(raw, 1))
