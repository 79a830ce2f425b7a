"""Leases: who may command the vehicle, and what happens when that right expires (docs/architecture.md §3).

``LeaseBook`` is the whole lease state of one vehicle as one immutable value, in the style of the Spot SDK's
``lease.py`` and PX4's failsafe framework: every transition takes the time as an argument and returns a new book
plus what happened (``Outcome``). No clock, socket or MAVLink framing lives here, so the rules can be tested on
their own and replayed from a journal. The book is the public face; each concept it holds has a file of its own:

    lease_terms    the vocabulary: LeaseId, Holder, ExpireReason, LeaseEvent, Check, Outcome ...
    lease_guard    enforcement, the stale-command guard: the verdict on one command (§3.4)
    lease_root     the root lease: epochs, acquire, release, takeover and auto-grant rules (§3.1, §3.8)
    lease_ledger   the execution-lease sequence: claims, expiry triggers, re-arm, subleases (§3.2-§3.7)
    link_watch     the owner's link: whether COMMS_LOST or LINK_REGAINED happened (§3.5, §6)
    lease_journal  the book as JSON and back

Vocabulary (patent US 2022/0197292): ``[E]`` is the root lease with epoch E, ``[E,i]`` execution lease i, and
``[E,i,j,...]`` its subleases. The *current* execution lease is the lowest-index lease that has not expired.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from link.parameters import default
from vehicle import lease_guard, lease_journal, lease_ledger, lease_root
from vehicle.frozen import evolve
from vehicle.lease_guard import RETURN_IN_PROGRESS
from vehicle.lease_root import epoch_before
from vehicle.lease_terms import (
    NO_INDEX,
    Check,
    ExecutionLease,
    ExpireReason,
    Holder,
    LeaseEvent,
    LeaseId,
    LeaseState,
    Outcome,
    QueuedCommand,
    RejectReason,
    ServiceBlock,
    Verdict,
)
from vehicle.link_watch import LinkWatch, Trigger, WatchConfig

if TYPE_CHECKING:
    from vehicle.params import Params

__all__ = [
    "NO_INDEX", "RETURN_IN_PROGRESS", "Check", "ExecutionLease", "ExpireReason", "Holder", "LeaseBook",
    "LeaseConfig", "LeaseEvent", "LeaseId", "LeaseState", "Outcome", "QueuedCommand", "RejectReason",
    "ServiceBlock", "Verdict", "epoch_before",
]


@dataclass(frozen=True)
class LeaseConfig:
    """The parameters the rules depend on (LNK_*, RTL_REARM, LEASE_*); defaults from the parameter table."""

    link_timeout: float = default("LNK_TIMEOUT")
    regain_s: float = default("LNK_REGAIN_S")
    contact_gap: float = default("LNK_GOOD_S")  # the longest gap between messages that still counts as contact
    min_quality: float = default("LNK_MIN_Q")  # owner's delivery below this for link_timeout is lost too
    rearm: bool = bool(default("RTL_REARM"))
    autogrant: bool = bool(default("LEASE_AUTOGRANT"))
    stale_take: bool = bool(default("LEASE_STALE_TAKE"))

    @classmethod
    def from_params(cls, params: Params) -> LeaseConfig:
        return cls(link_timeout=params["LNK_TIMEOUT"], regain_s=params["LNK_REGAIN_S"],
                   contact_gap=params["LNK_GOOD_S"], min_quality=params["LNK_MIN_Q"],
                   rearm=bool(params["RTL_REARM"]), autogrant=bool(params["LEASE_AUTOGRANT"]),
                   stale_take=bool(params["LEASE_STALE_TAKE"]))

    @property
    def watch(self) -> WatchConfig:
        """The part of the configuration the owner's link watch works with."""
        return WatchConfig(timeout=self.link_timeout, regain_s=self.regain_s, contact_gap=self.contact_gap,
                           min_quality=self.min_quality)


@dataclass(frozen=True)
class LeaseBook:
    """The whole lease state of one vehicle. Immutable; every method returns a new book."""

    config: LeaseConfig = field(default_factory=LeaseConfig)
    epoch: int | None = None
    owner: int | None = None  # MAVLink sysid of the ground station holding the root
    owner_compid: int = 0
    leases: tuple[ExecutionLease, ...] = ()  # the live sequence; expired leases are dropped after their event
    next_index: int = 0
    chains: int = 0
    plan: tuple[ServiceBlock, ...] = (ServiceBlock(),)
    claims: tuple[tuple[int, LeaseId], ...] = ()  # (sysid, last lease it claimed)
    queue: tuple[QueuedCommand, ...] = ()
    link: LinkWatch = field(default_factory=LinkWatch)  # the owner's link (kept in step with ``config``)
    last_reason: ExpireReason = ExpireReason.NONE
    takeover_allowed: bool = False
    last_epoch: int | None = None

    # ----- queries -----------------------------------------------------------------------------------------
    @property
    def current(self) -> ExecutionLease | None:
        return self.leases[0] if self.leases else None

    @property
    def current_id(self) -> LeaseId | None:
        cur = self.current
        return None if cur is None or self.epoch is None else LeaseId(self.epoch, (cur.index,))

    @property
    def scheduled(self) -> tuple[ExecutionLease, ...]:
        return self.leases[1:]

    @property
    def returning(self) -> bool:
        """A service block of the return plan holds the current lease: the return is running."""
        return bool(self.leases) and self.leases[0].holder is Holder.RETURN_SERVICE

    def lease(self, index: int) -> ExecutionLease | None:
        for lease in self.leases:
            if lease.index == index:
                return lease
        return None

    def claimed_by(self, sysid: int) -> LeaseId | None:
        for s, lid in self.claims:
            if s == sysid:
                return lid
        return None

    def link_up(self) -> bool:
        return self.owner is not None and not self.link.lost

    def owner_stale(self, t: float) -> bool:
        return lease_root.owner_stale(self, t)

    # ----- enforcement (lease_guard) -----------------------------------------------------------------------
    def check(self, sender: int, claim: LeaseId | None = None) -> Check:
        """Verdict for a state-changing command from ``sender`` carrying ``claim`` (None: the lease the sender
        last claimed)."""
        return lease_guard.check(self, sender, claim)

    # ----- the root lease (lease_root) ---------------------------------------------------------------------
    def acquire(self, sysid: int, compid: int, t: float, seed: int = 0, allow_takeover: bool = False) -> Outcome:
        return lease_root.acquire(self, sysid, compid, t, seed, allow_takeover)

    def release(self, sysid: int, t: float) -> Outcome:
        return lease_root.release(self, sysid, t)

    def take_refusal(self, sysid: int, t: float) -> str | None:
        return lease_root.take_refusal(self, sysid, t)

    def may_take(self, sysid: int, t: float) -> bool:
        """Whether ``sysid`` may take the root now (see ``take_refusal``)."""
        return lease_root.take_refusal(self, sysid, t) is None

    def admit(self, sender: int, compid: int, t: float, seed: int = 0) -> Outcome:
        return lease_root.admit(self, sender, compid, t, seed)

    # ----- the owner's link (link_watch, consumed by lease_ledger) -----------------------------------------
    def heard(self, sysid: int, t: float, seq: int | None = None) -> LeaseBook:
        """A message from the owner (MAVLink sequence number ``seq``) keeps the lease alive; the link watch
        measures its delivery, and ``tick`` evaluates the triggers."""
        if sysid != self.owner:
            return self
        return evolve(self, link=self.link.heard(t, seq))  # (``evolve``, not ``replace``: 1.1 % of the tick)

    def tick(self, t: float) -> Outcome:
        """Consume the link watch's trigger: COMMS_LOST of an operator lease, LINK_REGAINED of a service block
        (§3.5). The watch alone decides whether the link was lost or regained."""
        out = self.tick_changes(t)
        return Outcome(self) if out is None else out

    def tick_changes(self, t: float, place_holds: bool = True) -> Outcome | None:
        """``tick``, with None for "the same book, nothing happened": the answer of nearly every 20 ms tick, for
        which the vehicle loop then builds no ``Outcome``. ``place_holds`` False: the link map says the link does
        not reliably hold where the robot is, so a regain does not halt the running return there
        (``lease_ledger.on_link``)."""
        if self.owner is None:
            return None
        link, trigger = self.link.step(t)
        if trigger is Trigger.NONE:
            return None if link is self.link else Outcome(replace(self, link=link))
        return lease_ledger.on_link(self, link, trigger, t, place_holds)

    def regained_here(self, t: float) -> Outcome:
        """A return that heard its owner again where the map said the link does not hold has reached a place that
        does: its chain ends now, as LINK_REGAINED (``lease_ledger.regained_here``)."""
        return lease_ledger.regained_here(self, t)

    # ----- the execution-lease sequence (lease_ledger) -----------------------------------------------------
    def claim(self, sysid: int, epoch: int, index: int, t: float) -> tuple[Outcome, Check]:
        return lease_ledger.claim(self, sysid, epoch, index, t)

    def expire(self, sysid: int, epoch: int, index: int, t: float) -> tuple[Outcome, Check]:
        return lease_ledger.expire(self, sysid, epoch, index, t)

    def expire_current(self, sysid: int, t: float) -> tuple[Outcome, Check]:
        return lease_ledger.expire_current(self, sysid, t)

    def finish(self, index: int, reason: ExpireReason, t: float) -> Outcome:
        return lease_ledger.finish(self, index, reason, t)

    def interrupt(self, t: float, reason: ExpireReason) -> Outcome:
        """The robot was taken out of the book's hands from outside it (companion mode: the autopilot's pilot or its
        own failsafe changed mode, or the autopilot stopped answering): the current lease and everything scheduled
        behind it expire together, and a fresh operator lease waits, unclaimed, for the operator to resume
        (docs/architecture.md §3.6). Nothing to end (no owner, or already awaiting a claim): the same book."""
        cur = self.current
        if self.owner is None or cur is None or (cur.holder is Holder.OPERATOR and not cur.claimed):
            return Outcome(self)
        out = lease_ledger.advance(replace(self, leases=(cur,), queue=()), t, reason)
        return out._replace(dropped=self.queue + out.dropped)

    def issue_sublease(self, parent: LeaseId) -> tuple[LeaseBook, LeaseId]:
        return lease_ledger.issue_sublease(self, parent)

    def schedule_plan(self, plan: Iterable[ServiceBlock], t: float, store: bool = True) -> Outcome:
        return lease_ledger.schedule_plan(self, plan, t, store)

    def enqueue(self, command: QueuedCommand) -> LeaseBook:
        return lease_ledger.enqueue(self, command)

    def with_config(self, config: LeaseConfig) -> LeaseBook:
        return replace(self, config=config, link=self.link.with_config(config.watch))

    # ----- journal (lease_journal) -------------------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        """A JSON-able picture of the book (block payloads must themselves be JSON-able)."""
        return lease_journal.snapshot(self)

    @classmethod
    def restore(cls, snap: dict[str, Any]) -> LeaseBook:
        config = LeaseConfig(**snap["config"])
        return cls(config=config, **lease_journal.restored_fields(snap, config.watch))
