"""The link layer of the live map: the vehicle's link map (``linkmap.csv``, ``link/linkmap_format.py``) as the page
draws it.

The page's data comes from whatever gives the station the CSV bytes: the vehicle itself, which offers the file over
MAVLink FTP (``vehicle_source``, what ``returnlink gcs map`` uses), or a file a simulator run wrote
(``returnlink gcs map --linkmap FILE``). This module turns bytes into the layer, so every source shares it: bytes
in, plain lists out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from gcs.file_transfer import Download
from link.linkmap_format import FILE_NAME, LinkMapFormatError, MapCell, decode

if TYPE_CHECKING:
    from gcs.station import GroundStation

FETCH_PERIOD = 5.0  # s between fetches of the vehicle's map (a few kB each)
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


class VehicleSource:
    """The vehicle's own link map over MAVLink FTP: a fresh download every FETCH_PERIOD s of the station's clock,
    the last whole file given meanwhile (None until one has arrived; a vehicle without the file stays None).

    Called by the map page under the session's lock; the station's loop carries the transfer."""

    def __init__(self, gs: GroundStation, period: float = FETCH_PERIOD) -> None:
        self.gs, self.period = gs, period
        self.last: bytes | None = None
        self.download: Download | None = None
        self.started = -math.inf

    def __call__(self) -> bytes | None:
        d = self.download
        if d is not None and d.done:
            if d.ok:
                self.last = bytes(d.data)
            self.download = None
        if self.download is None and self.gs.t - self.started >= self.period:
            self.download, self.started = self.gs.fetch(FILE_NAME), self.gs.t
        return self.last
