"""The radio's timed events of a scenario, as both lockstep runs (the native one and the firmware's) apply them:
jamming (``jam``, ``unjam``: windows in which a station's radio hears nothing and is heard by nobody), a
station's radio going down and up (``kill_gcs``, ``revive_gcs``) and a station's transmit power changing by
``value`` dB (``power``: its range shrinks or grows, and a place where the link held may hold it no longer)."""

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


RADIO_EVENTS = frozenset(("jam", "unjam", "kill_gcs", "revive_gcs", "power"))


def radio_event(ev, station, jams: Jams, t: float) -> bool:
    """Apply the radio event ``ev`` (due at ``t``) to ``jams`` or to ``station`` (anything with ``alive`` and
    ``power_dbm``; None: the event names no station of the run). False: ``ev`` is not a radio event, for the caller
    to apply."""
    if ev.action not in RADIO_EVENTS:
        return False
    if ev.action == "jam":
        jams.jam(ev.t, ev.duration, ev.station)
    elif ev.action == "unjam":
        jams.unjam(t)
    elif station is None:
        pass
    elif ev.action == "power":
        station.power_dbm += ev.value  # both directions: the link budget is one figure per station (link.radio)
    else:
        station.alive = ev.action == "revive_gcs"
    return True
