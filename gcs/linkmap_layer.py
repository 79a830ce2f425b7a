"""The link layer of the live map: the vehicle's link map (``linkmap.csv``, ``link/linkmap_format.py``) as the page
draws it.

The page's data comes from whatever gives the station the CSV bytes: today a file a simulator run wrote, or the
simulator's own state (``returnlink gcs map --linkmap FILE``); a vehicle serving the file over MAVLink FTP plugs in
the same way, as one more source of bytes. This module only turns bytes into the layer, so every source shares it.
Pure: bytes in, plain lists out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

from link.linkmap_format import LinkMapFormatError, MapCell, decode

LinkMapSource = Callable[[], bytes | None]  # the current linkmap.csv, or None while there is none


def cell_size(cells: list[MapCell]) -> float | None:
    """The grid's cell size, from the smallest spacing between cell centres (None: fewer than two cells)."""
    gaps = {round(abs(a - b), 6) for axis in (0, 1) for a, b in _neighbours(sorted({c[axis] for c in cells}))}
    gaps.discard(0.0)
    return min(gaps) if gaps else None


def _neighbours(values: list[float]) -> list[tuple[float, float]]:
    return list(zip(values[:-1], values[1:], strict=True))


def layer(data: bytes) -> dict:
    """The page's link layer from linkmap.csv bytes: ``{"cell": metres, "cells": [[north, east, delivery,
    observations], ...], "error": None}``; delivery is None where nothing was expected. A file that cannot be read
    gives an empty layer and the reason (the map page keeps working)."""
    try:
        cells = decode(data)
    except LinkMapFormatError as e:
        return {"cell": None, "cells": [], "error": f"linkmap.csv {e}"}
    size = cell_size(cells) or 1.0
    return {"cell": size, "error": None,
            "cells": [[c.north, c.east, None if not math.isfinite(c.delivery) else round(c.delivery, 3),
                       c.observations] for c in cells]}


def file_source(path: Path) -> LinkMapSource:
    """A source reading ``path`` on every call (a run writing it anew is picked up), None while it is missing."""
    def read() -> bytes | None:
        try:
            return path.read_bytes()
        except OSError:
            return None

    return read
