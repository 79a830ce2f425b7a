"""Parameters (DESIGN §5): names, defaults, ranges and meaning, plus .parm files in the MAVProxy/ArduPilot format.

The table here is the metadata; ``params/returnlink.parm`` holds the defaults a vehicle boots with (a test keeps
the two in step). A set outside the range is refused and the old value stays: the MAVLink endpoint then
re-broadcasts the unchanged PARAM_VALUE with a STATUSTEXT giving this module's reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from vehicle.storage import StoredFileError, read_text, write_atomic


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
    ParamSpec("LNK_REGAIN_S", 1.0, 0.0, 10.0, "s", "owner heard continuously this long -> LINK_REGAINED"),
    ParamSpec("LNK_GOOD_S", 1.5, 0.1, 10.0, "s", "a crumb is link-good if the owner was heard within this"),
    ParamSpec("RTL_MAX_DISP", 50.0, 1.0, 10000.0, "m", "max displacement of one return block"),
    ParamSpec("RTL_MAX_TIME", 300.0, 0.0, 3600.0, "s", "a return block gives up after this (0 = no limit)"),
    ParamSpec("RTL_SPEED", 0.0, 0.0, 5.0, "m/s", "return speed; 0 = the speed used outbound"),
    ParamSpec("RTL_TARGET", 0, 0, 2, "", "LINK / ORIGIN / HEADING", integer=True),
    ParamSpec("RTL_REGAIN_ACT", 0, 0, 1, "", "on link regained: 0 halt and hold, 1 continue to target", integer=True),
    ParamSpec("RTL_REARM", 1, 0, 1, "", "reschedule the return plan behind every fresh operator lease", integer=True),
    ParamSpec("RTL_ARRIVE_R", 1.0, 0.1, 10.0, "m", "arrival radius"),
    ParamSpec("TRL_SPACING", 0.5, 0.05, 10.0, "m", "minimum distance between recorded crumbs"),
    ParamSpec("TRL_TOL", 0.25, 0.01, 5.0, "m", "simplification tolerance (degrades upward only when memory is full)"),
    ParamSpec("TRL_LOOP_D", 1.0, 0.1, 10.0, "m", "trail segments closer than this close a loop"),
    ParamSpec("TRL_MAX_PTS", 2000, 50, 100000, "", "memory bound of the trail", integer=True),
    ParamSpec("LEASE_AUTOGRANT", 1, 0, 1, "", "plain clients get the root implicitly", integer=True),
    ParamSpec("LEASE_STALE_TAKE", 1, 0, 1, "", "a silent owner may be taken over", integer=True),
    ParamSpec("LNK_MIN_Q", 0.25, 0.0, 0.9, "",
              "owner's packet delivery below this for LNK_TIMEOUT also counts as lost (0 = silence only)"),
)
BY_NAME = {s.name: s for s in SPECS}
DEFAULTS_FILE = Path(__file__).resolve().parent.parent / "params" / "returnlink.parm"


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


class Params:
    """Current values. Mutable on purpose: the endpoint owns one and journals it to a .parm file."""

    def __init__(self, values: dict[str, float] | None = None) -> None:
        self.values = {s.name: float(s.default) for s in SPECS}
        for k, v in (values or {}).items():
            self.values[k] = validate(k, v)

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def set(self, name: str, value: float) -> float:
        """Store a validated value and return it; on ParamError the old value stays."""
        self.values[name] = validate(name, value)
        return self.values[name]

    def index(self, name: str) -> int:
        return [s.name for s in SPECS].index(name)

    def names(self) -> list[str]:
        return [s.name for s in SPECS]


class _BadLine(ValueError):
    def __init__(self, line: int, what: str) -> None:
        super().__init__(what)
        self.line, self.what = line, what


def _parse(text: str) -> dict[str, float]:
    """The values of a .parm text, or _BadLine(line, what) at the first line that is not ``NAME VALUE``."""
    out: dict[str, float] = {}
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").split()
        if len(parts) != 2:
            raise _BadLine(n, f"expected 'NAME VALUE', got {raw.strip()!r}")
        try:
            value = float(parts[1])
        except ValueError:
            raise _BadLine(n, f"{parts[1]!r} is not a number") from None
        try:
            out[parts[0]] = validate(parts[0], value)
        except ParamError as e:
            raise _BadLine(n, str(e)) from None
    return out


def parse_parm(text: str, source: str = "<parm>") -> dict[str, float]:
    """MAVProxy/ArduPilot .parm: ``NAME VALUE`` (or ``NAME,VALUE``) per line, ``#`` comments."""
    try:
        return _parse(text)
    except _BadLine as e:
        raise ParamError(f"{source}:{e.line}: {e.what}") from None


def read_parm_file(path: Path) -> dict[str, float]:
    """A .parm file the vehicle boots from, read strictly: StoredFileError naming the file and line if it is
    empty, ends in the middle of a line, or has a line that is not a valid ``NAME VALUE``.

    Our own files are written whole (``save_parm``) and always end with a newline, so a file that does not was cut
    short by something else: its last value may be a truncated number that still parses (``5`` of ``50``).
    """
    text = read_text(path)
    if not text.strip():
        raise StoredFileError(path, 1, "empty file, no parameters")
    if not text.endswith("\n"):
        raise StoredFileError(path, text.count("\n") + 1, "incomplete last line (no newline at the end of the file)")
    try:
        return _parse(text)
    except _BadLine as e:
        raise StoredFileError(path, e.line, e.what) from None


def format_parm(values: dict[str, float]) -> str:
    lines = ["# returnlink parameters (MAVProxy/ArduPilot .parm format)"]
    for s in SPECS:
        if s.name in values:
            v = values[s.name]
            lines.append(f"{s.name:<16} {int(v) if s.integer else f'{v:g}'}")
    return "\n".join(lines) + "\n"


def save_parm(path: Path, values: dict[str, float]) -> None:
    """Replace the vehicle's .parm file atomically: a crash or a reader mid-save sees the old or the new file."""
    write_atomic(path, format_parm(values))


def load_defaults(path: Path = DEFAULTS_FILE) -> Params:
    """The parameters to boot with: ``path`` read strictly (StoredFileError if damaged), or the built-in
    defaults when there is no such file yet."""
    if path.is_file():
        return Params(read_parm_file(path))
    return Params()
