"""Mission items as they travel (docs/architecture.md §4): the MISSION_ITEM_INT form and the local frame's origin,
shared by the vehicle's mission server and the ground station's client.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH_R = 6378137.0


@dataclass(frozen=True)
class Item:
    """A mission item exactly as received (MISSION_ITEM_INT fields), so a download returns what was uploaded."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int


@dataclass(frozen=True)
class Origin:
    """The local frame's origin on the globe, for global <-> local conversion of positions."""

    lat: float = 47.397742
    lon: float = 8.545594
    alt: float = 488.0

    def to_global(self, x: float, y: float) -> tuple[float, float]:
        lat = self.lat + math.degrees(x / EARTH_R)
        lon = self.lon + math.degrees(y / (EARTH_R * math.cos(math.radians(self.lat))))
        return lat, lon

    def to_local(self, lat: float, lon: float) -> tuple[float, float]:
        x = math.radians(lat - self.lat) * EARTH_R
        y = math.radians(lon - self.lon) * EARTH_R * math.cos(math.radians(self.lat))
        return x, y


def item_from_message(m, x: int | None = None, y: int | None = None) -> Item:
    """A MISSION_ITEM_INT (or a MISSION_ITEM with its x/y already scaled) as an ``Item``."""
    return Item(m.seq, m.frame, m.command, m.current, m.autocontinue, m.param1, m.param2, m.param3, m.param4,
                int(m.x) if x is None else x, int(m.y) if y is None else y, m.z, getattr(m, "mission_type", 0))
