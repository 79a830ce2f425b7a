"""The execution-lease sequence: which lease is current, what comes next, and how one gives way to the next
(docs/architecture.md §3.2, §3.3, §3.5-§3.7).

The ledger holds ``[E,0]``, ``[E,1]``, ... with their holders; the current lease is the lowest index not expired.
It moves on by a trigger (COMMS_LOST and LINK_REGAINED from the owner's link watch, OPERATOR_EXPIRE, NEWER_LEASE,
a service block's COMPLETED / TIMEOUT / STUCK), releases or drops the commands queued under scheduled leases as it
goes, and re-arms the return plan behind every fresh operator lease while the link is up. After a chain ends, a
fresh *unclaimed* operator lease is current: the operator resumes by claiming it.

Every function takes the book (and the time) and returns a new book or an ``Outcome``; none keeps state.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

from vehicle import lease_guard
from vehicle.lease_terms import (
    NO_INDEX,
    Book,
    BookState,
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
    refused,
)
from vehicle.link_watch import LinkWatch, Trigger

SERVICE_ENDINGS = (ExpireReason.COMPLETED, ExpireReason.TIMEOUT, ExpireReason.STUCK)


# ----- the operator's transitions ------------------------------------------------------------------------------
def claim(book: BookState, sysid: int, epoch: int, index: int, t: float) -> tuple[Outcome, Check]:
    """MAV_CMD_LEASE_CLAIM: -1 claims the current unclaimed operator lease ("resume by incrementing the lease");
    any other index claims the next free index at or above it (NEWER_LEASE)."""
    if book.owner is None or sysid != book.owner:
        return Outcome(book), refused(RejectReason.NOT_IN_CONTROL, "not the owner")
    if epoch != book.epoch:
        return Outcome(book), refused(RejectReason.WRONG_EPOCH, f"epoch {epoch} is not {book.epoch}")
    cur = book.leases[0]
    if index < 0:
        if cur.holder is not Holder.OPERATOR or cur.claimed:
            return Outcome(book), refused(RejectReason.INVALID, "the current lease is not an unclaimed operator lease")
        lid = LeaseId(epoch, (cur.index,))
        leases = (replace(cur, claimed=True), *book.leases[1:])
        new = arm(replace(book, leases=leases, claims=_set_claim(book.claims, sysid, lid)), t)
        return Outcome(new), Check(Verdict.EXECUTE, lid)
    new_index = max(index, book.next_index)
    if new_index > NO_INDEX - 1:
        return Outcome(book), refused(RejectReason.INVALID, "lease index space exhausted")
    lid = LeaseId(epoch, (new_index,))
    fresh = ExecutionLease(new_index, Holder.OPERATOR, LeaseState.CURRENT, started_at=t)
    event = LeaseEvent(t, epoch, cur.index, new_index, ExpireReason.NEWER_LEASE, Holder.OPERATOR)
    new = replace(book, leases=(fresh,), next_index=new_index + 1, queue=(),
                  claims=_set_claim(book.claims, sysid, lid), last_reason=ExpireReason.NEWER_LEASE)
    return Outcome(arm(new, t), (event,), dropped=book.queue), Check(Verdict.EXECUTE, lid)


def expire(book: BookState, sysid: int, epoch: int, index: int, t: float) -> tuple[Outcome, Check]:
    """MAV_CMD_LEASE_EXPIRE (or RTL): the explicit OPERATOR_EXPIRE trigger of the current lease."""
    chk = lease_guard.check(book, sysid, LeaseId(epoch, (index,)))
    if chk.verdict is Verdict.QUEUE:
        chk = refused(RejectReason.INVALID, "only the current lease can be expired", chk.lease)
    if not chk.executes and not (chk.reason is RejectReason.EXPIRED and _is_unclaimed_current(book, index)):
        return Outcome(book), chk
    return advance(book, t, ExpireReason.OPERATOR_EXPIRE), Check(Verdict.EXECUTE, chk.lease)


def expire_current(book: BookState, sysid: int, t: float) -> tuple[Outcome, Check]:
    """RTL button / RTL mode from a plain client: expire whatever the owner currently holds."""
    if book.owner is None or sysid != book.owner:
        return Outcome(book), refused(RejectReason.NOT_IN_CONTROL, "not the owner")
    if book.leases[0].holder is not Holder.OPERATOR:
        return Outcome(book), Check(Verdict.EXECUTE, book.current_id, detail="a return is already running")
    return advance(book, t, ExpireReason.OPERATOR_EXPIRE), Check(Verdict.EXECUTE, book.current_id)


# ----- the return service's transitions ------------------------------------------------------------------------
def finish(book: BookState, index: int, reason: ExpireReason, t: float) -> Outcome:
    """The auto-return service reports that its block ended: COMPLETED, TIMEOUT or STUCK."""
    if reason not in SERVICE_ENDINGS:
        raise ValueError(f"{reason.name} is not a service completion")
    cur = book.current
    if cur is None or cur.index != index or cur.holder is not Holder.RETURN_SERVICE:
        return Outcome(book)
    return advance(book, t, reason)


def issue_sublease(book: Book, parent: LeaseId) -> tuple[Book, LeaseId]:
    """Divide the current lease: the new sublease supersedes every older one under ``parent`` (§3.3)."""
    cur = book.current
    if cur is None or parent.epoch != book.epoch or not parent.path or parent.path[0] != cur.index:
        raise ValueError(f"{parent} is not the current lease")
    depth = len(parent.sub)
    newest = cur.newest_sub
    n = newest[depth] + 1 if len(newest) > depth and newest[:depth] == parent.sub else 0
    child = parent.child(n)
    leases = (replace(cur, newest_sub=child.sub), *book.leases[1:])
    return replace(book, leases=leases), child


def schedule_plan(book: BookState, plan: Iterable[ServiceBlock], t: float, store: bool = True) -> Outcome:
    """Schedule a return plan behind the current operator lease. ``store`` (a mission upload) also makes it the
    plan re-armed from now on; without it (a one-off return, a plan started mid-way) the stored plan stays the one
    re-armed afterwards."""
    plan = tuple(plan)
    new = replace(book, plan=plan) if store else book
    if book.owner is None or book.leases[0].holder is not Holder.OPERATOR:
        return Outcome(new)
    kept = new.leases[:1]
    still_queued = tuple(q for q in new.queue if q.lease.path[0] == kept[0].index)
    gone = tuple(q for q in new.queue if q.lease.path[0] != kept[0].index)
    new = replace(new, leases=kept, queue=still_queued)
    return Outcome(arm(new, t, force=True, plan=plan), dropped=gone)


def enqueue(book: Book, command: QueuedCommand) -> Book:
    """Hold a command sent under a scheduled lease until that lease becomes current."""
    return replace(book, queue=(*book.queue, command))


# ----- the owner's link --------------------------------------------------------------------------------------
def on_link(book: BookState, link: LinkWatch, trigger: Trigger, t: float, place_holds: bool = True) -> Outcome:
    """Consume a trigger of the owner's link watch (§3.5): LOST expires a current operator lease (COMMS_LOST);
    REGAINED ends a service block that halts on regain and the rest of its chain (LINK_REGAINED), and otherwise
    re-arms the plan behind the operator lease now that the link is up again.

    Where the link map says the link does not reliably hold (``place_holds`` False, docs/architecture.md §6) the
    regain is taken (the watch is no longer lost) but the halting block runs on to the place that does; the
    vehicle then ends the chain there with ``regained_here``."""
    new = replace(book, link=link)
    cur = new.leases[0]
    if trigger is Trigger.LOST:
        if cur.holder is Holder.OPERATOR:
            return advance(new, t, ExpireReason.COMMS_LOST)
        return Outcome(new)
    if cur.holder is Holder.RETURN_SERVICE and cur.block is not None and cur.block.halt_on_regain:
        if not place_holds:
            return Outcome(new)
        return _end_chain(new, t, ExpireReason.LINK_REGAINED)
    return Outcome(arm(new, t))


def regained_here(book: BookState, t: float) -> Outcome:
    """LINK_REGAINED, deferred by ``on_link`` to a place the map vouches for: the current halting block and its
    chain end now, if the link is still up (lost again, the next regain decides afresh)."""
    cur = book.leases[0] if book.leases else None
    if (cur is None or cur.holder is not Holder.RETURN_SERVICE or cur.block is None or not cur.block.halt_on_regain
            or book.link.lost):
        return Outcome(book)
    return _end_chain(book, t, ExpireReason.LINK_REGAINED)


# ----- how the sequence moves on -------------------------------------------------------------------------------
def advance(book: BookState, t: float, reason: ExpireReason) -> Outcome:
    """The current lease expires; the next scheduled one (or a fresh unclaimed operator lease) is current, the
    commands queued under it are released, and those under leases now behind it are dropped."""
    cur = book.leases[0]
    rest = book.leases[1:]
    if rest:
        nxt = replace(rest[0], state=LeaseState.CURRENT, started_at=t)
        leases = (nxt, *rest[1:])
        next_index = book.next_index
    else:
        nxt = ExecutionLease(book.next_index, Holder.OPERATOR, LeaseState.CURRENT, claimed=False, started_at=t)
        leases = (nxt,)
        next_index = book.next_index + 1
    released = tuple(q for q in book.queue if q.lease.path[0] == nxt.index)
    queue = tuple(q for q in book.queue if q.lease.path[0] > nxt.index)
    dropped = tuple(q for q in book.queue if q.lease.path[0] < nxt.index)
    new = replace(book, leases=leases, next_index=next_index, queue=queue, last_reason=reason)
    event = LeaseEvent(t, book.epoch or 0, cur.index, nxt.index, reason, nxt.holder)
    return Outcome(arm(new, t), (event,), released, dropped)


def _end_chain(book: BookState, t: float, reason: ExpireReason) -> Outcome:
    """LINK_REGAINED: the current block and the rest of its contingency chain expire together."""
    chain = book.leases[0].chain
    rest = tuple(lease for lease in book.leases[1:] if lease.chain != chain or lease.holder is Holder.OPERATOR)
    gone = {lease.index for lease in book.leases[1:]} - {lease.index for lease in rest}
    dropped = tuple(q for q in book.queue if q.lease.path[0] in gone)
    new = replace(book, leases=(book.leases[0], *rest), queue=tuple(q for q in book.queue
                                                                    if q.lease.path[0] not in gone))
    out = advance(new, t, reason)
    return out._replace(dropped=dropped + out.dropped)


def arm(book: Book, t: float, force: bool = False, plan: tuple[ServiceBlock, ...] | None = None) -> Book:
    """Re-arm (§3.7): behind a current operator lease, with the link up, schedule the return plan (``plan``, or
    the stored one). Without RTL_REARM only the first operator lease of a root is armed, unless ``force``d."""
    plan = book.plan if plan is None else plan
    if book.owner is None or not book.leases or not plan:
        return book
    cur = book.leases[0]
    if cur.holder is not Holder.OPERATOR or len(book.leases) > 1 or book.link.lost:
        return book
    if not force and not book.config.rearm and (cur.index != 0 or not cur.claimed):
        return book
    chain = book.chains + 1
    blocks = tuple(
        ExecutionLease(book.next_index + k, Holder.RETURN_SERVICE, LeaseState.SCHEDULED, block=b, chain=chain)
        for k, b in enumerate(plan)
    )
    return replace(book, leases=(cur, *blocks), next_index=book.next_index + len(blocks), chains=chain)


def _is_unclaimed_current(book: BookState, index: int) -> bool:
    cur = book.current
    return cur is not None and cur.index == index and cur.holder is Holder.OPERATOR and not cur.claimed


def _set_claim(claims: tuple[tuple[int, LeaseId], ...], sysid: int, lid: LeaseId) -> tuple[tuple[int, LeaseId], ...]:
    return (*((s, c) for s, c in claims if s != sysid), (sysid, lid))
