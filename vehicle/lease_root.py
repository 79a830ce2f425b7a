"""The root lease: who owns the vehicle, how a ground station takes it, and when another may take it over
(docs/architecture.md §3.1, §3.8).

A new root is a new epoch, and a new epoch expires every lease of the old one, so a command still carrying it is
refused WRONG_EPOCH. Plain clients get the root implicitly (LEASE_AUTOGRANT), and a silent owner may be taken
over (LEASE_STALE_TAKE), but never while its return runs: that silence is what the return exists to protect.
Every function takes the book and the time and returns a new book; none keeps state.
"""

from __future__ import annotations

from dataclasses import replace

from vehicle.lease_guard import RETURN_IN_PROGRESS
from vehicle.lease_ledger import arm
from vehicle.lease_terms import (
    BookState,
    ExecutionLease,
    ExpireReason,
    Holder,
    LeaseEvent,
    LeaseId,
    LeaseState,
    Outcome,
)
from vehicle.link_watch import EPS, LinkWatch


def epoch_after(previous: int | None, seed: int) -> int:
    """A fresh uint16 epoch (0 means 'none' on the wire).

    The first epoch comes from ``seed`` only in the lockstep simulator, so its runs repeat; a real-time vehicle
    starts its book at ``epoch_before`` of an epoch drawn by ``vehicle.epochs`` (OS random, clear of its recent
    boots). Later ones count up, so no epoch repeats until 65535 roots have been issued.
    Merely differing from the previous epoch is not enough: A, B, A would revive A's stale commands.
    """
    if previous is None:
        return (seed * 2654435761 + 40503) % 0xFFFF + 1
    return previous % 0xFFFF + 1


def epoch_before(epoch: int) -> int:
    """The ``last_epoch`` a book must start from for its first root to get ``epoch`` (a real-time vehicle's boot
    epoch, drawn from the OS random source by ``vehicle.epochs``)."""
    if not 1 <= epoch <= 0xFFFF:
        raise ValueError(f"epoch {epoch} outside 1..65535")
    return (epoch - 2) % 0xFFFF + 1


def acquire(book: BookState, sysid: int, compid: int, t: float, seed: int = 0,
            allow_takeover: bool = False) -> Outcome:
    """A ground station takes the root: a fresh epoch E and the operator lease [E,0] (§3.1)."""
    had_owner = book.owner is not None
    epoch = epoch_after(book.last_epoch, seed)
    old_current = book.current.index if book.current else None
    dropped = book.queue
    new = replace(
        book, epoch=epoch, owner=sysid, owner_compid=compid, next_index=1, chains=0,
        leases=(ExecutionLease(0, Holder.OPERATOR, LeaseState.CURRENT, started_at=t),),
        claims=((sysid, LeaseId(epoch, (0,))),), queue=(), link=LinkWatch(book.config.watch).heard(t),
        takeover_allowed=allow_takeover, last_epoch=epoch,
        last_reason=ExpireReason.ROOT_REPLACED if had_owner else book.last_reason,
    )
    reason = ExpireReason.ROOT_REPLACED if had_owner else ExpireReason.NONE
    event = LeaseEvent(t, epoch, old_current, 0, reason, Holder.OPERATOR)
    return Outcome(arm(new, t), (event,), dropped=dropped)


def release(book: BookState, sysid: int, t: float) -> Outcome:
    """The owner gives the vehicle up: every lease expires and nobody owns it."""
    if sysid != book.owner:
        return Outcome(book)
    old = book.current.index if book.current else None
    new = replace(book, epoch=None, owner=None, owner_compid=0, leases=(), claims=(), queue=(),
                  link=LinkWatch(book.config.watch), last_reason=ExpireReason.RELEASED, takeover_allowed=False)
    event = LeaseEvent(t, book.epoch or 0, old, None, ExpireReason.RELEASED, Holder.NONE)
    return Outcome(new, (event,), dropped=book.queue)


def owner_stale(book: BookState, t: float) -> bool:
    """The owner has been silent for LNK_TIMEOUT (or never heard): a stale owner may be taken over."""
    age = book.link.age(t)
    return age is None or age >= book.config.link_timeout - EPS


def take_refusal(book: BookState, sysid: int, t: float) -> str | None:
    """Why ``sysid`` may not take the root now, or None if it may (unowned, its own, allowed takeover, or a stale
    owner).

    A running return is never taken over (§3.8): the owner is silent exactly because its link is lost, which is
    what the return exists to protect, so a silent owner only becomes fair game once the chain has ended
    (AWAITING_CLAIM)."""
    if book.owner is None or book.owner == sysid:
        return None
    if book.returning:
        return RETURN_IN_PROGRESS
    if book.takeover_allowed or (book.config.stale_take and owner_stale(book, t)):
        return None
    return f"owned by GCS {book.owner}; takeover not allowed"


def admit(book: BookState, sender: int, compid: int, t: float, seed: int = 0) -> Outcome:
    """Plain clients (§3.8): a state-changing command from a ground station that may take the vehicle implicitly
    acquires the root when auto-grant is on. Returns the book unchanged otherwise. An explicit allow-takeover is
    for REQUEST_OPERATOR_CONTROL only: a stream of commands never takes over."""
    if sender == book.owner or not book.config.autogrant:
        return Outcome(book)
    if book.owner is None or (not book.returning and book.config.stale_take and owner_stale(book, t)):
        return acquire(book, sender, compid, t, seed)
    return Outcome(book)
