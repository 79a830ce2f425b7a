"""What a run keeps of the onboard lease machinery as it runs, for the §7 metrics and the plots: the link losses
and regains the vehicle declared, and one record per return block. Every plant that flies returnlink's ``Vehicle``
(natively, ``sim.plants.native``, or as the companion beside the firmware, ``sim.plants.companion``) keeps the same
record, and ``sim.metrics`` reads it.

A mixin of the one loop (``sim.runner.Run``), because the record is a few calls inside its tick:
``_vehicle_state(v)`` before the vehicle's tick and ``_vehicle_ticked(v, t, before)`` after it,
``_track_block(s, t, pos, cur, returning)`` once a tick after the per-tick row was appended to ``self._rows`` (rows
start with t, true x, true y, est x, est y), ``_close_block`` when the run ends. The host provides ``vehicle``,
``contingency``, ``world``, ``t``, ``policy``, ``frame_offset`` and ``_rows``.

It reads the vehicle only as any observer may (``vehicle.port``): its status snapshot (``Status``), the parameters,
the trail's crumbs, and the log of its lease transitions (``log``), which it keeps a copy of as they come
(``lease_log``); never the core's own fields.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.policies.base import Baseline
from sim.scenario import PLAN_COMMANDS
from vehicle.core import DT
from vehicle.lease import LeaseEvent
from vehicle.port import Status

COMMAND_NAMES = {num: name for name, num in PLAN_COMMANDS.items()}


@dataclass
class BlockRecord:
    """One return block as it ran. ``start``, ``end``, ``target_true``, distance and displacement are in the true
    frame; ``target`` and ``route`` are the vehicle's plan, in its estimate frame."""

    index: int
    started: float
    start: tuple[float, float]
    command: str = ""
    target: tuple[float, float] | None = None
    target_true: tuple[float, float] | None = None  # where the robot truly was at the target (crumb or map place)
    max_disp_allowed: float = math.inf
    ended: float | None = None
    end: tuple[float, float] | None = None
    reason: str = ""
    route: np.ndarray | None = None
    route_obj: object = None
    distance: float = 0.0
    max_disp: float = 0.0
    driving_s: float = 0.0  # time the return commanded motion
    collisions: int = 0  # during this block
    collisions0: int = 0  # the world's count when it started


class LeaseRecord:
    """The record (see the module docstring); ``_start_record`` in the host's constructor."""

    _rows: list[tuple]

    def _start_record(self) -> None:
        self.blocks: list[BlockRecord] = []
        self.link_backs: list[tuple[float, float | None]] = []  # (link regained, start of the contact run)
        self.regains: list[tuple[float, float | None]] = []  # (LINK_REGAINED time, start of the contact run)
        self.stale_setpoints = 0  # teleop setpoints the run's own audit found outside the announced current lease
        self.announced: tuple[int, int | None] | None = None  # (epoch, current index) from LEASE_EVENTs
        self.losses: list[tuple[float, float | None]] = []  # (COMMS_LOST time, owner last heard before it)
        # when each loss's trigger condition became true: LNK_TIMEOUT after the owner was last heard (silence), or
        # the tick the owner's delivery estimate fell below LNK_MIN_Q (quality), whichever came first
        self.loss_conditions: list[float | None] = []
        self._log: list[LeaseEvent] = []  # the vehicle's lease transitions read so far (``lease_log``)
        self._log_of = None  # ... of this vehicle (a plant boots its vehicle once; a new one starts a new copy)

    def _read_log(self, v) -> int:
        """Copy the lease transitions ``v`` logged since the last read; how many were read before these."""
        if v is not self._log_of:
            self._log_of, self._log = v, []
        n = len(self._log)
        new = v.log(n)
        if new:
            self._log.extend(new)
        return n

    @property
    def lease_log(self) -> list[LeaseEvent]:
        """Every lease transition of the run's vehicle since it booted, oldest first (empty: none aboard)."""
        v = self.vehicle
        if v is not None:
            self._read_log(v)
        return self._log

    def _vehicle_state(self, v) -> tuple:
        """What ``_vehicle_ticked`` compares with after the tick (the transitions of the commands heard before the
        tick are read here, and are not the tick's)."""
        self._read_log(v)
        link = v.status().book.link
        return len(self._log), link.last_heard, link.lost, link.low

    def _vehicle_ticked(self, v, t: float, before: tuple) -> None:
        """What the metrics need of the tick just run: when the owner's link came back, and each new lease event
        (the lease the runner's own audit expects, the losses and the regains)."""
        n_events, heard, was_lost, low = before
        book = v.status().book
        link = book.link
        if was_lost and not link.lost and book.owner is not None:
            self.link_backs.append((t, link.contact_since))
        self._read_log(v)
        if len(self._log) > n_events:
            for e in self._log[n_events:]:
                self.announced = (e.epoch, e.current)
                if e.reason.name == "COMMS_LOST":
                    self.losses.append((e.t, heard))
                    silence = None if heard is None else heard + v.params["LNK_TIMEOUT"]
                    self.loss_conditions.append(min(silence, t) if low and silence is not None else silence)
                elif e.reason.name == "LINK_REGAINED":
                    self.regains.append((e.t, link.contact_since))

    def _track_block(self, s: Status, t: float, pos: tuple[float, float], cur, returning: bool) -> None:
        """The block the current lease is, opened, closed and measured (``pos``: the true position this tick)."""
        blocks = self.blocks
        blk = blocks[-1] if blocks and blocks[-1].ended is None else None
        if blk is not None and (not returning or cur.index != blk.index):
            self._close_block()
            blk = None
        if returning and blk is None:
            blk = BlockRecord(cur.index, t, (float(pos[0]), float(pos[1])), self._command_of(cur),
                              collisions0=self.world.collisions)
            self.blocks.append(blk)
        if blk is not None:
            rows = self._rows
            if len(rows) > 1:
                a = rows[-2]
                blk.distance += math.hypot(pos[0] - a[1], pos[1] - a[2])
                if s.command_out != (0.0, 0.0):
                    blk.driving_s += DT
            blk.collisions = self.world.collisions - blk.collisions0
            blk.max_disp = max(blk.max_disp, math.hypot(pos[0] - blk.start[0], pos[1] - blk.start[1]))
            self._plan_of(s, blk)

    def _command_of(self, lease) -> str:
        """The block's mission items by name (RETURN_TO_LINK, ...), or the baseline policy that drives it."""
        if isinstance(self.contingency, Baseline):
            return self.policy.upper()
        items = lease.block.payload if lease.block is not None else ()
        return "+".join(COMMAND_NAMES.get(it.command, str(it.command)) for it in items)

    def _plan_of(self, s: Status, blk: BlockRecord) -> None:
        """Target, route and displacement limit of ``blk``, taken only from the service state of that very lease
        (``s``: the snapshot of this tick): the state left over from the block before must never lend its limit to
        the next one."""
        c = self.contingency
        if isinstance(c, Baseline):
            if c.route is not None and c.route is not blk.route_obj:
                blk.route_obj, blk.route, blk.target = c.route, c.route, c.target
                # every baseline heads for home, where the estimator started: the true start of the run
                blk.target_true = self._true_of(0) if c.target is not None and self._rows else None
            return
        st = s.block
        if st is None or s.block_index != blk.index:
            return
        if st.route is not None and st.route is not blk.route_obj:
            blk.route_obj = st.route
            blk.route = st.route.points if blk.route is None else np.vstack([blk.route, st.route.points])
            if blk.target is None and st.route.target is not None:
                blk.target = st.route.target
                blk.target_true = self._target_true(st.route)
        if blk.max_disp_allowed == math.inf:
            blk.max_disp_allowed = st.max_displacement

    def _target_true(self, route) -> tuple[float, float] | None:
        """Where in the true frame the robot was at the place ``route`` heads for. A crumb target: when the crumb
        was laid. The map's place lies on the way back but is not a crumb (a kept trail stretch may be metres long):
        where the robot was when its estimate passed nearest the place, in the ticks recorded so far."""
        if not route.by_map:
            k, times = route.target_index, self.vehicle.crumbs().times
            return self.true_at(float(times[k])) if 0 <= k < len(times) else None
        rows = self._rows
        if not rows:
            return None
        ox, oy = self.frame_offset
        est = np.array([(r[3], r[4]) for r in rows], dtype=float)
        d = np.hypot(est[:, 0] - (route.target[0] + ox), est[:, 1] - (route.target[1] + oy))
        if not np.isfinite(d).any():  # no estimate yet (a companion before its autopilot booted)
            return None
        return self._true_of(int(np.nanargmin(d)))

    def _close_block(self) -> None:
        if not self.blocks or self.blocks[-1].ended is not None:
            return
        blk = self.blocks[-1]
        blk.ended = self.t
        blk.end = self._true_of(-1) if self._rows else blk.start
        for ev in self.lease_log:
            if ev.expired == blk.index and ev.t >= blk.started - 1e-9:
                blk.reason = ev.reason.name
                break

    def true_at(self, t: float) -> tuple[float, float]:
        """True position at simulated time ``t`` (nearest recorded tick)."""
        return self._true_of(min(len(self._rows) - 1, max(0, int(round(t / DT)) - 1)))

    def _true_of(self, k: int) -> tuple[float, float]:
        """The true position recorded at tick ``k`` (a row, so no column need be built during the run)."""
        row = self._rows[k]
        return row[1], row[2]

    @property
    def lease_events(self) -> list[dict]:
        return [{"t": round(e.t, 3), "expired": e.expired, "current": e.current, "reason": e.reason.name}
                for e in self.lease_log]
