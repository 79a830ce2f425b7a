"""The autopilot parameters companion mode needs (``returnlink companion --check`` / ``--configure``).

The companion never changes the autopilot silently: ``--check`` prints each parameter, what it needs to be and
why, and which differ; ``--configure`` sets the ones that differ and prints each change. The rules are values
here, so the check, the configure step and the warning at start-up all read the same table.

The backstop needs the autopilot's GCS failsafe on, with an action that stops the rover, and a timeout that a 1 Hz
keepalive never trips but a dead companion does within seconds. The companion commands the autopilot with its own
system id, so the autopilot must accept MAVLink from system ids outside its ground-station range.
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


@dataclass(frozen=True)
class Row:
    need: Need
    value: float | None  # None: the autopilot has no such parameter (another firmware version)

    @property
    def ok(self) -> bool:
        return self.value is None or self.need.ok(self.value)


def check(values: dict[str, float]) -> list[Row]:
    """Each need against the autopilot's ``values``."""
    return [Row(n, values.get(n.name)) for n in NEEDS]


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
