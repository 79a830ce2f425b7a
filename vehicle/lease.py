"""Leases: who may command the vehicle, and what happens when that right expires (docs/architecture.md §3).

``LeaseBook`` is the whole lease state of one vehicle as one immutable value, in the style of the Spot SDK's
``lease.py`` and PX4's failsafe framework: every transition takes the time as an argument and returns a new book
plus what happened (``Outcome``). No clock, socket or MAVLink framing lives here, so the rules can be tested on
their own. The book is the public face; each concept it holds has a file of its own (the rules are functions over
the one value, not objects with state of their own: a transition such as a new root touches the root's epoch and
every execution lease at once, and one immutable value makes that one step, never two half-applied ones):

    lease_terms    the vocabulary: LeaseId, Holder, ExpireReason, LeaseEvent, Check, Outcome ..., and the book's
                   state the rules read and return (BookState, LeaseConfig; LeaseBook adds the rules as methods)
    lease_guard    enforcement, the stale-command guard: the verdict on one command (§3.4)
    lease_root     the root lease: epochs, acquire, release, takeover and auto-grant rules (§3.1, §3.8)
    lease_ledger   the execution-lease sequence: claims, expiry triggers, re-arm, subleases (§3.2-§3.7)
    link_watch     the owner's link: whether COMMS_LOST or LINK_REGAINED happened (§3.5, §6)

Vocabulary (patent US 2022/0197292): ``[E]`` is the root lease with epoch E, ``[E,i]`` execution lease i, and
``[E,i,j,...]`` its subleases. The *current* execution lease is the lowest-index lease that has not expired.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace

from vehicle import lease_guard, lease_ledger, lease_root
from vehicle.lease_guard import RETURN_IN_PROGRESS
from vehicle.lease_root import epoch_before
from vehicle.lease_terms import (
    NO_INDEX,
    BookState,
    Check,
    ExecutionLease,
    ExpireReason,
    Holder,
    LeaseConfig,
    LeaseEvent,
    LeaseId,
    LeaseState,
    Outcome,
    QueuedCommand,
    RejectReason,
    ServiceBlock,
    Verdict,
)
from vehicle.link_watch import Trigger

__all__ = [
    "NO_INDEX", "RETURN_IN_PROGRESS", "BookState", "Check", "ExecutionLease", "ExpireReason", "Holder", "LeaseBook",
    "LeaseConfig", "LeaseEvent", "LeaseId", "LeaseState", "Outcome", "QueuedCommand", "RejectReason",
    "ServiceBlock", "Verdict", "epoch_before",
]


@dataclass(frozen=True)
class LeaseBook(BookState):
    """The whole lease state of one vehicle (``BookState``: its fields and queries) with the rules as its methods.
    Immutable; every method returns a new book."""

    # ----- queries (the rest: ``BookState``) ---------------------------------------------------------------
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

    def admit(self, sender: int, compid: int, t: float, seed: int = 0) -> Outcome:
        return lease_root.admit(self, sender, compid, t, seed)

    # ----- the owner's link (link_watch, consumed by lease_ledger) -----------------------------------------
    def heard(self, sysid: int, t: float, seq: int | None = None) -> LeaseBook:
        """A message from the owner (MAVLink sequence number ``seq``) keeps the lease alive; the link watch
        measures its delivery, and ``tick`` evaluates the triggers."""
        if sysid != self.owner:
            return self
        return replace(self, link=self.link.heard(t, seq))

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
