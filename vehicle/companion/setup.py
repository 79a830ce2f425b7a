"""The autopilot parameters companion mode needs (``returnlink companion --check`` / ``--configure``).

The companion never changes the autopilot silently: ``--check`` prints each parameter, what it needs to be and
why, and which differ; ``--configure`` sets the ones that differ and prints each change. The rules are values
here, so the check, the configure step and the warning at start-up all read the same table.

The backstop needs the autopilot's GCS failsafe on, with an action that stops the rover, and a timeout that a 1 Hz
keepalive never trips but a dead companion does within seconds. The companion commands the autopilot with its own
system id, so the autopilot must accept MAVLink from system ids outside its ground-station range.

PX4 (``PX4_NEEDS``, docs/architecture.md §11.2) has two failsafes in the backstop: its data-link loss (NAV_DLL_ACT
after COM_DL_LOSS_T without a GCS heartbeat: the companion's keepalive is the only one it hears) for a companion
that dies at any time, and its Offboard loss (COM_OBL_RC_ACT after COM_OF_LOSS_T without a setpoint) for one that
dies mid-return. The Offboard loss is also the dead-man over the owner's own Offboard drive: when the owner falls
silent PX4 must not drive on to its last setpoint, so COM_OF_LOSS_T is the native rover's teleop timeout, 0.5 s
(measured in the tunnel, seed 1: at PX4's default 1 s the rover drove 0.4 m deeper before it stopped and the link
came back 0.6 s later). Both must be Hold: PX4's Return is a straight drive
to the launch point through whatever lies between, and its Offboard-loss default, Position mode, needs sticks a
rover driven from a companion does not have. PX4 takes commands from any system id: nothing to open there.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Need:
    name: str
    wanted: str  # what it must be, in words
    why: str
    ok: Callable[[float], bool]
    fix: Callable[[float], float]  # the value --configure sets, from the current one


NEEDS: tuple[Need, ...] = (
    Need("FS_GCS_ENABLE", "1", "the backstop: a dead or hung companion ends in the GCS failsafe",
         lambda v: v == 1, lambda v: 1.0),
    Need("FS_ACTION", "2 or 4", "the failsafe stops the rover: Hold (2), or SmartRTL else Hold (4)",
         lambda v: v in (2, 4), lambda v: 2.0),
    Need("FS_GCS_TIMEOUT", "2..5", "s without the 1 Hz keepalive before the failsafe",
         lambda v: 2 <= v <= 5, lambda v: min(5.0, max(2.0, v))),
    Need("MAV_OPTIONS", "bit 0 clear", "commands from the companion's own system id are accepted (4.7+)",
         lambda v: int(v) & 1 == 0, lambda v: float(int(v) & ~1)),
    Need("SYSID_ENFORCE", "0", "commands from the companion's own system id are accepted (before 4.7)",
         lambda v: v == 0, lambda v: 0.0),
)

PX4_NEEDS: tuple[Need, ...] = (
    Need("NAV_DLL_ACT", "1", "the backstop: a dead companion (no keepalive) ends in Hold, not Return's straight drive",
         lambda v: v == 1, lambda v: 1.0),
    Need("COM_DL_LOSS_T", "2..5", "s without the 1 Hz keepalive before the data-link failsafe",
         lambda v: 2 <= v <= 5, lambda v: min(5.0, max(2.0, v))),
    Need("COM_OF_LOSS_T", "0.3..0.5", "s of Offboard silence before Hold: the owner's drive stops as soon as the "
         "native rover's teleop does, a dead companion's return too",
         lambda v: 0.3 <= v <= 0.5, lambda v: min(0.5, max(0.3, v))),
    Need("COM_OBL_RC_ACT", "5", "a companion dead mid-return leaves the rover in Hold (Offboard loss)",
         lambda v: v == 5, lambda v: 5.0),
)


def needs_for(autopilot: int | None) -> tuple[Need, ...]:
    """The parameters the companion needs of the autopilot its HEARTBEAT names (MAV_AUTOPILOT: 12 PX4, else
    ArduPilot's)."""
    return PX4_NEEDS if autopilot == 12 else NEEDS


@dataclass(frozen=True)
class Row:
    need: Need
    value: float | None  # None: the autopilot has no such parameter (another firmware version)

    @property
    def ok(self) -> bool:
        return self.value is None or self.need.ok(self.value)


def check(values: dict[str, float], needs: tuple[Need, ...] = NEEDS) -> list[Row]:
    """Each need (ArduPilot's unless told) against the autopilot's ``values``."""
    return [Row(n, values.get(n.name)) for n in needs]


def differing(rows: list[Row]) -> list[Row]:
    return [r for r in rows if not r.ok]


def report(rows: list[Row]) -> str:
    """The table ``--check`` prints."""
    lines = [f"{'parameter':<16} {'now':>8}  {'needs':<12} {'':<8} why"]
    for r in rows:
        now = "-" if r.value is None else f"{r.value:g}"
        state = "absent" if r.value is None else ("ok" if r.ok else "DIFFERS")
        lines.append(f"{r.need.name:<16} {now:>8}  {r.need.wanted:<12} {state:<8} {r.need.why}")
    return "\n".join(lines)


# ----- the return's range sensors: advice, not a need (a rover without them is driven as before, §11.4) ----------
RANGEFINDERS = 6  # ArduPilot's RNGFND1..6 are read (a rover's ring of rangefinders)
ORIENT_WORDS = {0: "forward", 1: "forward-right", 2: "right", 3: "back-right", 4: "back", 5: "back-left", 6: "left",
                7: "forward-left"}  # RNGFNDn_ORIENT that point a beam along the ground: the ones the return uses
PX4_RANGE_DRIVERS = ("SENS_EN_SF1XX", "SENS_EN_LL40LS", "SENS_EN_TRANGER")  # a few of PX4's distance sensor drivers
STREAM_WORDS = ("  DISTANCE_SENSOR: the companion asks for it at 10 Hz itself (MAV_CMD_SET_MESSAGE_INTERVAL on its "
                "port);")


def range_params(autopilot: int | None) -> list[str]:
    """The parameters ``range_report`` reads."""
    if autopilot == 12:
        return list(PX4_RANGE_DRIVERS)
    names = [f"RNGFND{n}_{p}" for n in range(1, RANGEFINDERS + 1) for p in ("TYPE", "ORIENT")]
    return names + ["PRX1_TYPE"]


def range_report(values: dict[str, float], autopilot: int | None) -> str:
    """What ``--check`` prints about the range sensors the return keeps its body off: which of the autopilot's
    parameters give it some, and how their readings reach the companion."""
    lines = ["range sensors (the return keeps its body off what they see; none: no standoff, as before):"]
    usable = False
    if autopilot == 12:
        on = [f"{n} {values[n]:g}" for n in PX4_RANGE_DRIVERS if values.get(n)]
        usable = bool(on)
        lines.append(f"  {', '.join(on)}: a distance sensor driver enabled" if on else
                     f"  {', '.join(PX4_RANGE_DRIVERS)}: none enabled (or another driver: any distance sensor PX4 "
                     "reports counts)")
        lines.append(STREAM_WORDS + " PX4 streams it at 0.5 Hz otherwise")
    else:
        for n in range(1, RANGEFINDERS + 1):
            kind, orient = values.get(f"RNGFND{n}_TYPE"), values.get(f"RNGFND{n}_ORIENT")
            if not kind:
                continue
            where = ORIENT_WORDS.get(int(orient)) if orient is not None else None
            usable = usable or where is not None
            lines.append(f"  RNGFND{n}_TYPE {kind:g}, RNGFND{n}_ORIENT "
                         + (f"{orient:g}: facing {where}" if where else f"{orient if orient is None else int(orient)}"
                            ": not along the ground (the return uses ORIENT 0..7)"))
        prx = values.get("PRX1_TYPE")
        if prx:
            usable = True
            lines.append(f"  PRX1_TYPE {prx:g}: a proximity sensor, its sectors sent as DISTANCE_SENSOR")
        elif not usable:
            lines.append("  RNGFNDn_TYPE (with RNGFNDn_ORIENT 0..7) or PRX1_TYPE (a 360-degree lidar): none set up")
        lines.append(STREAM_WORDS + " its stream group is MAVn_EXTRA3 (SRn_EXTRA3 before 4.7)")
    lines.append("  a lidar driver's OBSTACLE_DISTANCE from any component of the vehicle is heard as well")
    if not usable:
        lines.append("  none set up here: unless another component sends OBSTACLE_DISTANCE, the return keeps no "
                     "standoff")
    return "\n".join(lines)
