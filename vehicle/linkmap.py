"""The owner's link over space: which places held the link, measured by every packet expected and delivered there
(docs/architecture.md §6, "The link map").

Why a map and not the crumbs' tags: a crumb's tag says what one moment was like (the owner heard within LNK_GOOD_S),
and the first packet that gets through at the fringe of coverage makes it "good". A return that stops there stops
where the link holds one moment in three, and loses it again a moment later (issue 21: two loss cycles per run at
-20 dBm). A place is known by many moments: the map keeps, per grid cell of the vehicle's local estimated frame,

* ``expected``: the owner's packets sent while the robot was in the cell, from the sender's own rate (its MAVLink
  sequence numbers over time) times the time spent there, so a silence counts as the packets it swallowed, booked to
  the cells the robot crossed during it, not to the cell where the next packet happens to arrive;
* ``delivered``: the owner's packets that arrived there;
* ``observations``: slices of ``OBS_S`` seconds (or a visit, if shorter) the robot spent in the cell with the
  sender's rate known; one slice is one look at the place, the unit "enough observations" is counted in;
* the mean RSSI of the vehicle's radio there, when the radio reports one.

A place *reliably holds* when it has at least LNK_MAP_OBS observations and the Wilson lower confidence bound on its
delivery (``Z`` = one-sided 95 %) meets the regain's own threshold (``vehicle.link_watch.REGAIN_QUALITY``; or
LNK_MIN_Q + LNK_MAP_MARGIN where that is stricter): a lucky packet at the fringe, or a short look at a cell, never
makes a place reliable, and a long good look makes it so even if a few packets were lost. Why the regain's number
and not LNK_MIN_Q's (DESIGN §6.2): a place is worth returning to only if LINK_REGAINED can come there, and a
looser bound vouched for places where it never came (issue 38; docs/evidence.md, "The measurements behind the
vehicle's code").

Cost and memory (the map runs in the 50 Hz loop, docs/architecture.md §8): ``at`` is a few float operations and one
dict lookup when the robot changes cell; ``packet`` is a handful. Memory is bounded by LNK_MAP_CELLS: when a new cell
would exceed it, the cells farthest from the robot (then the longest unvisited, then by key, so the choice is
deterministic) are dropped, an eighth of the bound at once, so the O(n log n) eviction is paid once per n/8 new
cells: amortised O(log n) per new cell and O(1) per tick.

Pure in the house sense: time is an argument, nothing reads a clock or a socket. Mutable like the trail: the vehicle
owns one and feeds it every tick.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from link.linkmap_format import MapCell
from link.parameters import default
from vehicle.link_watch import EPS, REGAIN_QUALITY

if TYPE_CHECKING:
    from collections.abc import Iterator

    import numpy as np

    from vehicle.params import Params

SEQ_SPACE = 256  # MAVLink's uint8 sequence number
OBS_S = 0.5  # s: one observation of a cell (a visit shorter than this is one too)
Z = 1.645  # Wilson bound's z: one-sided 95 %
RATE_MAX_GAP = 2.0  # s: a sequence gap after a longer silence says nothing about the sender's rate (it may wrap)
RATE_DECAY = 0.9  # per packet: the sender's rate follows a change within a few tens of packets
MAX_RATE = 200.0  # packets/s: a rate beyond this is a glitch (a restarted sender), not a measure
SEEN_BITS = 64  # sequence numbers behind the newest whose arrival is remembered (duplicates are not deliveries)
SEEN_MASK = (1 << SEEN_BITS) - 1
EVICT_SHARE = 8  # when full, drop 1/EVICT_SHARE of the cells at once (amortised cost, see the module docstring)


@dataclass(frozen=True)
class MapConfig:
    """The LNK_MAP_* parameters and the LNK_MIN_Q the bound is judged against; defaults from the parameter table."""

    cell: float = default("LNK_MAP_CELL")
    max_cells: int = int(default("LNK_MAP_CELLS"))
    min_obs: int = int(default("LNK_MAP_OBS"))
    margin: float = default("LNK_MAP_MARGIN")
    min_quality: float = default("LNK_MIN_Q")

    @classmethod
    def from_params(cls, params: Params) -> MapConfig:
        return cls(cell=params["LNK_MAP_CELL"], max_cells=int(params["LNK_MAP_CELLS"]),
                   min_obs=int(params["LNK_MAP_OBS"]), margin=params["LNK_MAP_MARGIN"],
                   min_quality=params["LNK_MIN_Q"])

    @property
    def threshold(self) -> float:
        """The lower bound a reliable place must meet: the regain's (``REGAIN_QUALITY``), or LNK_MIN_Q +
        LNK_MAP_MARGIN where that is stricter (kept below 1, so a perfect place can reach it)."""
        return max(REGAIN_QUALITY, min(0.95, self.min_quality + self.margin))


def wilson_lower(delivered: float, expected: float, z: float = Z) -> float:
    """Wilson score lower bound of a delivery ratio: ``delivered`` of ``expected`` packets (0 when nothing was
    expected). Monotone: more delivered of the same expected, or the same ratio over more packets, never lowers it."""
    n = expected
    if n <= 0:
        return 0.0
    p = min(1.0, max(0.0, delivered / n))
    z2 = z * z
    centre = p + z2 / (2 * n)
    spread = z * math.sqrt(max(0.0, p * (1 - p) / n + z2 / (4 * n * n)))
    return max(0.0, (centre - spread) / (1 + z2 / n))


class _Cell:
    """A cell's counters (mutable, with slots: one per place, updated in the tick)."""

    __slots__ = ("delivered", "expected", "last_t", "observations", "rssi_n", "rssi_sum")

    def __init__(self, t: float) -> None:
        self.expected = 0.0
        self.delivered = 0
        self.observations = 0
        self.rssi_sum = 0.0
        self.rssi_n = 0
        self.last_t = t


class LinkMap:
    """Per cell: the owner's packets expected and delivered, observations, RSSI. Feed it ``at`` every tick (the
    estimated position), ``packet`` for every packet from the owner, ``rssi`` when the radio reports; ask it
    ``reliable(x, y)`` and ``first_reliable(route)``; ``cells()`` is what the operator sees
    (``link.linkmap_format.encode(m.cells())`` is linkmap.csv)."""

    def __init__(self, config: MapConfig | None = None) -> None:
        self.config = config or MapConfig()
        self._cells: dict[tuple[int, int], _Cell] = {}
        self._key: tuple[int, int] | None = None  # the robot's cell
        self._cell: _Cell | None = None
        self._x = self._y = 0.0
        self._t: float | None = None  # the last ``at``
        self._slice_t = 0.0  # when the robot's current observation slice began
        self._slice_expected = 0.0
        # the sender's rate, from its sequence numbers: decayed sums of sequence advance and of time
        self._seq: int | None = None
        self._seen = 0  # bit i: the packet i numbers behind the newest arrived
        self._seq_t = 0.0
        self._adv = 0.0
        self._dt = 0.0
        self.evictions = 0

    # ----- inputs ------------------------------------------------------------------------------------------
    @property
    def rate(self) -> float | None:
        """The owner's packets per second as sent (None until two packets in a row have told it)."""
        return self._adv / self._dt if self._dt > 0 else None

    def packet(self, t: float, seq: int | None) -> None:
        """A packet from the owner at ``t`` with MAVLink sequence number ``seq``: delivered in the robot's cell, and a
        measure of the rate the owner sends at. A duplicate (same sequence number) is not a delivery."""
        if seq is not None:
            seq %= SEQ_SPACE
            last = self._seq
            if last is None:
                self._seen = 1
            else:
                d = (seq - last) % SEQ_SPACE
                if d == 0:
                    return  # a duplicate of the newest
                if d >= SEQ_SPACE // 2:  # behind the newest: a late packet, or a duplicate of one
                    behind = SEQ_SPACE - d
                    if behind >= SEEN_BITS or self._seen >> behind & 1:
                        return
                    self._seen |= 1 << behind
                    seq = last  # the newest number stays
                else:
                    gap = t - self._seq_t
                    if 0 < gap <= RATE_MAX_GAP and d / gap <= MAX_RATE:
                        self._adv = RATE_DECAY * self._adv + d
                        self._dt = RATE_DECAY * self._dt + gap
                    self._seen = (self._seen << d | 1) & SEEN_MASK
            self._seq, self._seq_t = seq, t
        cell = self._cell
        if cell is not None:
            cell.delivered += 1

    def forget_sender(self) -> None:
        """A new owner: its rate and sequence numbers are its own (what was measured stays on the map)."""
        self._seq, self._adv, self._dt, self._seen = None, 0.0, 0.0, 0

    def rssi(self, dbm: float) -> None:
        """The vehicle's radio reports the owner's signal strength: one sample for the robot's cell."""
        cell = self._cell
        if cell is not None and math.isfinite(dbm):
            cell.rssi_sum += dbm
            cell.rssi_n += 1

    def at(self, t: float, x: float, y: float) -> None:
        """The robot's estimated position at ``t`` (every tick): the time since the last call was spent in the
        cell it was in, and the packets the owner sent meanwhile are expected there."""
        last_t = self._t
        self._t = t
        cell = self._cell
        if cell is not None and last_t is not None:
            rate = self._adv / self._dt if self._dt > 0 else 0.0
            if rate > 0 and t > last_t:
                e = rate * (t - last_t)
                cell.expected += e
                self._slice_expected += e
            cell.last_t = t
        s = self.config.cell
        key = (math.floor(x / s), math.floor(y / s))
        self._x, self._y = x, y
        if key != self._key:
            self._close_slice()
            self._enter(key, t)
        elif t - self._slice_t >= OBS_S - 1e-9:
            self._close_slice()
            self._slice_t = t

    def _close_slice(self) -> None:
        """The robot's look at its cell ends: an observation, if the sender's rate made any packet expected."""
        if self._cell is not None and self._slice_expected > 0:
            self._cell.observations += 1
        self._slice_expected = 0.0

    def _enter(self, key: tuple[int, int], t: float) -> None:
        cells = self._cells
        cell = cells.get(key)
        if cell is None:
            if len(cells) >= self.config.max_cells:
                self._evict(key)
            cell = cells[key] = _Cell(t)
        self._key, self._cell, self._slice_t = key, cell, t

    def _evict(self, entering: tuple[int, int]) -> None:
        """Drop the cells farthest from the robot (then the longest unvisited, then by key): an eighth of the bound,
        so the next n/8 new cells cost nothing. The robot's own cell and the one it enters are kept."""
        self.evictions += 1
        n = max(1, self.config.max_cells // EVICT_SHARE)
        ex, ey = entering

        def rank(item: tuple[tuple[int, int], _Cell]) -> tuple[int, float, tuple[int, int]]:
            (i, j), c = item
            return (-((i - ex) ** 2 + (j - ey) ** 2), c.last_t, (i, j))

        keep = {self._key, entering}
        victims = heapq.nsmallest(n, ((k, c) for k, c in self._cells.items() if k not in keep), key=rank)
        for k, _ in victims:
            del self._cells[k]

    def with_config(self, config: MapConfig) -> None:
        """New parameters: a new cell size starts a new map (old cells no longer mean the same places); a smaller
        bound evicts at the next new cell."""
        if config.cell != self.config.cell:
            self._cells, self._key, self._cell = {}, None, None
        self.config = config

    # ----- queries -----------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._cells)

    def key(self, x: float, y: float) -> tuple[int, int]:
        s = self.config.cell
        return math.floor(x / s), math.floor(y / s)

    def lower(self, x: float, y: float) -> float:
        """Wilson lower bound on the delivery of the cell holding (x, y) (0: never measured)."""
        c = self._cells.get(self.key(x, y))
        return 0.0 if c is None else wilson_lower(c.delivered, c.expected)

    def reliable(self, x: float, y: float) -> bool:
        """Whether the map says the link reliably holds at (x, y): enough observations and a lower confidence
        bound on delivery that meets ``MapConfig.threshold`` (``_holds``)."""
        return self._holds(self.key(x, y))

    def _holds(self, key: tuple[int, int]) -> bool:
        """A cell looked at for LNK_MAP_OBS observations is judged alone. A cell crossed too fast for that (at
        2 m/s a 2 m cell is one second: two looks) is judged with the cells around it that the robot also
        crossed: a place is known by its neighbourhood, and a straight drive at speed must not leave the map
        vouching only for where the robot dawdled far back (issue 28: a companion's return drove 15 m past where
        the owner was last heard, to the one cell near home with enough looks). The pooled bound still counts
        every packet lost next door, so the fringe of coverage, whose neighbours beyond are dead, stays
        unreliable; a cell whose own looks saw the link fail never holds."""
        c = self._cells.get(key)
        cfg = self.config
        if c is None or c.expected <= 0:
            return False
        if c.observations >= cfg.min_obs:
            return wilson_lower(c.delivered, c.expected) >= cfg.threshold - EPS
        obs, expected, delivered = 0, 0.0, 0
        i, j = key
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                n = self._cells.get((i + di, j + dj))
                if n is not None:
                    obs, expected, delivered = obs + n.observations, expected + n.expected, delivered + n.delivered
        return obs >= cfg.min_obs and wilson_lower(delivered, expected) >= cfg.threshold - EPS

    def known(self) -> bool:
        """Whether any place is reliable (a map with none cannot disagree with anything)."""
        return any(self._holds(k) for k in self._cells)

    def poor(self, x: float, y: float) -> bool:
        """Whether the map has seen the link fail at (x, y): enough observations, and a delivery below the
        threshold a reliable place's bound must clear (a cell merely unknown is not poor)."""
        c = self._cells.get(self.key(x, y))
        cfg = self.config
        return (c is not None and c.observations >= cfg.min_obs and c.expected > 0
                and c.delivered / c.expected < cfg.threshold)

    def first_reliable(self, route: np.ndarray, skip: float = 0.0, poor: bool = False) -> tuple[int, float] | None:
        """Along polyline ``route`` (n, 2), from ``skip`` metres on, the first point in a reliable cell (with
        ``poor``: in a cell where the link was seen to fail), as (segment k, fraction u along it); None if none
        is. Sampled at a quarter cell, so no cell the route crosses is missed by more than a corner."""
        test = self.poor if poor else self.reliable
        step = 0.25 * self.config.cell
        walked = 0.0
        for k in range(len(route) - 1):
            ax, ay = float(route[k][0]), float(route[k][1])
            bx, by = float(route[k + 1][0]), float(route[k + 1][1])
            length = math.hypot(bx - ax, by - ay)
            if walked + length < skip:
                walked += length
                continue
            n = max(1, math.ceil(length / step))
            for m in range(n + 1):
                u = m / n
                if walked + u * length < skip - 1e-9:
                    continue
                if test(ax + u * (bx - ax), ay + u * (by - ay)):
                    return k, u
            walked += length
        return None

    def cells(self) -> Iterator[MapCell]:
        """Every cell, in key order (a stable file for the same run): centre, counts, delivery, bound, RSSI."""
        s = self.config.cell
        for (i, j) in sorted(self._cells):
            c = self._cells[(i, j)]
            delivery = min(1.0, c.delivered / c.expected) if c.expected > 0 else math.nan
            yield MapCell((i + 0.5) * s, (j + 0.5) * s, c.observations, c.expected, c.delivered, delivery,
                             wilson_lower(c.delivered, c.expected),
                             c.rssi_sum / c.rssi_n if c.rssi_n else math.nan, c.last_t)
