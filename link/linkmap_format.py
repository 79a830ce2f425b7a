"""``linkmap.csv``: the link map as a file (docs/architecture.md §6, "The link map"), shared by both ends.

The vehicle writes it (``sim run`` puts one in every output directory; a vehicle serves the same bytes to ground
stations), the ground station reads it for its map page. Both import this module and nothing of each other, the way
the .parm format lives in ``link/parameters.py``.

One row per cell of the vehicle's local frame as it knows it (x north, y east, metres; the cell's centre):

    north,east,observations,expected,delivered,delivery,lower,rssi_dbm,last_s

``delivery`` is delivered / expected (empty when nothing was expected yet), ``lower`` its Wilson lower confidence
bound (what "reliably good" is judged by), ``rssi_dbm`` the mean RSSI there (empty when no radio reported one),
``last_s`` the vehicle time the robot was last in the cell. Extra columns a later version adds are ignored by
``decode``; the nine above are the contract (north, east, observations, delivery and rssi_dbm at least).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

FILE_NAME = "linkmap.csv"  # the name the vehicle offers it under over MAVLink FTP, and sim run writes it under
COLUMNS = ("north", "east", "observations", "expected", "delivered", "delivery", "lower", "rssi_dbm", "last_s")
HEADER = ",".join(COLUMNS)


class MapCell(NamedTuple):
    """One cell of the link map."""

    north: float
    east: float
    observations: int
    expected: float
    delivered: int
    delivery: float  # nan: nothing expected yet
    lower: float
    rssi_dbm: float  # nan: no RSSI reported there
    last_s: float


class LinkMapFormatError(ValueError):
    """A linkmap.csv that cannot be read: ``line`` (1-based) and ``field`` say where."""

    def __init__(self, line: int, field: str, what: str) -> None:
        super().__init__(f"line {line}: {field}: {what}" if field else f"line {line}: {what}")
        self.line, self.field, self.what = line, field, what


def _num(x: float, nd: int) -> str:
    return "" if not math.isfinite(x) else f"{x:.{nd}f}".rstrip("0").rstrip(".") or "0"


def encode_row(c: MapCell) -> str:
    """One cell as a CSV line (no newline); unknown numbers as empty fields."""
    return ",".join((_num(c.north, 3), _num(c.east, 3), str(int(c.observations)), _num(c.expected, 2),
                     str(int(c.delivered)), _num(c.delivery, 4), _num(c.lower, 4), _num(c.rssi_dbm, 1),
                     _num(c.last_s, 2)))


def encode(cells: Iterable[MapCell]) -> bytes:
    """The whole file: the header, then one line per cell, UTF-8 with a final newline."""
    return ("\n".join([HEADER, *(encode_row(c) for c in cells)]) + "\n").encode("utf-8")


def _field(parts: list[str], k: int, name: str, line: int, integer: bool = False, optional: bool = False) -> float:
    text = parts[k].strip() if k < len(parts) else ""
    if text == "":
        if optional:
            return math.nan
        raise LinkMapFormatError(line, name, "missing")
    try:
        v = int(text) if integer else float(text)
    except ValueError:
        raise LinkMapFormatError(line, name, f"{text!r} is not a number") from None
    if not math.isfinite(v) or (integer and v < 0):
        raise LinkMapFormatError(line, name, f"{text!r} out of range")
    return v


def decode_row(text: str, line: int = 2, columns: tuple[str, ...] = COLUMNS) -> MapCell:
    """One CSV line back to a cell; LinkMapFormatError names the line and the field."""
    parts = text.split(",")
    at = {name: columns.index(name) for name in COLUMNS if name in columns}

    def get(name: str, integer: bool = False, optional: bool = False) -> float:
        if name not in at:
            return math.nan if optional else 0
        return _field(parts, at[name], name, line, integer, optional)

    delivery = get("delivery", optional=True)
    if math.isfinite(delivery) and not 0.0 <= delivery <= 1.0:
        raise LinkMapFormatError(line, "delivery", f"{delivery} outside 0..1")
    return MapCell(get("north"), get("east"), int(get("observations", integer=True)), get("expected", optional=True),
                   int(get("delivered", integer=True)), delivery, get("lower", optional=True),
                   get("rssi_dbm", optional=True), get("last_s", optional=True))


def decode(data: bytes | str) -> list[MapCell]:
    """A whole linkmap.csv back to cells. The header must name at least north, east, observations, delivery and
    rssi_dbm; columns may come in any order, unknown ones are ignored."""
    text = data.decode("utf-8") if isinstance(data, bytes) else data
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise LinkMapFormatError(1, "", "empty file, no header")
    columns = tuple(c.strip() for c in lines[0].split(","))
    missing = [c for c in ("north", "east", "observations", "delivery", "rssi_dbm") if c not in columns]
    if missing:
        raise LinkMapFormatError(1, missing[0], "column missing from the header")
    return [decode_row(raw, n, columns) for n, raw in enumerate(lines[1:], 2) if raw.strip()]
