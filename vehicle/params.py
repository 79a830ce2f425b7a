"""The vehicle's parameters (docs/architecture.md §5): current values and the .parm files it boots from and saves to.

The table (names, defaults, ranges, meaning) and the .parm text format live in ``link/parameters.py``, where the
ground station reaches them too; ``params/returnlink.parm`` holds the defaults a vehicle boots with (a test keeps
the two in step). A set outside the range is refused and the old value stays: the MAVLink endpoint then
re-broadcasts the unchanged PARAM_VALUE with a STATUSTEXT giving this module's reason.
"""

from __future__ import annotations

from pathlib import Path

from link.parameters import (  # noqa: F401 - the table and the .parm format, re-exported for existing importers
    BY_NAME,
    SPECS,
    BadLine,
    ParamError,
    ParamSpec,
    format_parm,
    parse_lines,
    parse_parm,
    validate,
)
from link.storage import StoredFileError, read_text, write_atomic

DEFAULTS_FILE = Path(__file__).resolve().parent.parent / "params" / "returnlink.parm"


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
        return parse_lines(text)
    except BadLine as e:
        raise StoredFileError(path, e.line, e.what) from None


def save_parm(path: Path, values: dict[str, float]) -> None:
    """Replace the vehicle's .parm file atomically: a crash or a reader mid-save sees the old or the new file."""
    write_atomic(path, format_parm(values))


def load_defaults(path: Path = DEFAULTS_FILE) -> Params:
    """The parameters to boot with: ``path`` read strictly (StoredFileError if damaged), or the built-in
    defaults when there is no such file yet."""
    if path.is_file():
        return Params(read_parm_file(path))
    return Params()
