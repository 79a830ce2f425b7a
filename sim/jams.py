"""Jamming from a scenario's timed events (``jam``, ``unjam``): windows in which a station's radio hears nothing
and is heard by nobody. One value both lockstep runs share, the native one and the firmware's."""

from __future__ import annotations

import math


class Jams:
    """(from, until, station) windows; station "" jams every station. Falsy while there are none, so the per-packet
    check costs nothing in the many runs that never jam."""

    def __init__(self) -> None:
        self.windows: list[tuple[float, float, str]] = []

    def __bool__(self) -> bool:
        return bool(self.windows)

    def jam(self, t: float, duration: float, station: str) -> None:
        """From ``t`` for ``duration`` s (0: until an unjam)."""
        self.windows.append((t, t + (duration or math.inf), station))

    def unjam(self, t: float) -> None:
        """Every window ends at ``t``."""
        self.windows = [(a, min(b, t), s) for a, b, s in self.windows]

    def jammed(self, station: str, t: float) -> bool:
        return bool(self.windows) and any(a <= t < b and (not s or s == station) for a, b, s in self.windows)
