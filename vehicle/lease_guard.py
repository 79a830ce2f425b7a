"""Enforcement: the verdict on one command from the lease it carries (docs/architecture.md §3.4).

This is the stale-command guard of the patent: a command is executed only under the current execution lease,
queued under a scheduled one, and refused, with its reason, under anything older, another epoch, a superseded
sublease or a lease nobody issued. It only reads the book; nothing here changes state, so the endpoint can ask
for every command and the vehicle loop for every teleop setpoint it is about to drive on.
"""

from __future__ import annotations

from vehicle.lease_terms import BookState, Check, Holder, LeaseId, RejectReason, Verdict, refused

RETURN_IN_PROGRESS = "return in progress"  # why a takeover (or a stranger's command) is refused during a return


def check(book: BookState, sender: int, claim: LeaseId | None = None) -> Check:
    """Verdict for a state-changing command from ``sender`` carrying ``claim``.

    ``claim`` None means a standard message with no lease field: it is checked against the lease the sender last
    claimed (docs/architecture.md §3.4).
    """
    if book.owner is None or sender != book.owner:
        why = RETURN_IN_PROGRESS if book.returning else "sender does not own the vehicle"
        return refused(RejectReason.NOT_IN_CONTROL, why, claim)
    if claim is None:
        claim = book.claimed_by(sender)
        if claim is None:
            return refused(RejectReason.EXPIRED, "no lease claimed")
    cur = book.leases[0]
    if claim.epoch != book.epoch:
        return refused(RejectReason.WRONG_EPOCH, f"epoch {claim.epoch} is not {book.epoch}", claim)
    if not claim.path:
        return refused(RejectReason.INVALID, "a root lease carries no commands", claim)
    index = claim.path[0]
    if index < cur.index:
        return refused(RejectReason.EXPIRED, f"{claim} expired; current is [{book.epoch},{cur.index}]", claim)
    if index == cur.index:
        if cur.holder is Holder.OPERATOR and not cur.claimed:
            return refused(RejectReason.EXPIRED, f"{claim} is not claimed yet", claim)
        sub = claim.path[1:]
        if sub and not sub_is_live(sub, cur.newest_sub):
            return refused(RejectReason.EXPIRED, f"sublease {claim} superseded", claim)
        return Check(Verdict.EXECUTE, claim)
    if book.lease(index) is not None:
        return Check(Verdict.QUEUE, claim)
    return refused(RejectReason.INVALID, f"{claim} does not exist; claim it first", claim)


def sub_is_live(sub: tuple[int, ...], newest: tuple[int, ...]) -> bool:
    """A sublease is live if it is the newest one issued or an ancestor of it (older siblings are superseded)."""
    if not newest:
        return sub == (0,)  # operator teleop runs under [E,i,0] before anything was divided
    return newest[: len(sub)] == sub
