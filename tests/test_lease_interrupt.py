"""``LeaseBook.interrupt`` / ``Vehicle.preempt``: the robot taken out of the book's hands from outside it (companion
mode: a pilot's mode switch, the autopilot's own failsafe, a lost autopilot) ends the current lease and its whole
chain, and the vehicle waits for a claim, as after LINK_REGAINED (docs/architecture.md §3.6)."""

from __future__ import annotations

from vehicle.lease import ExpireReason, Holder, LeaseBook, ServiceBlock


def chain_book() -> LeaseBook:
    """Owner 255, a two-block return plan running (the first block current after an explicit expire)."""
    book = LeaseBook(plan=(ServiceBlock(), ServiceBlock())).acquire(255, 190, 0.0).book
    out, _ = book.expire_current(255, 1.0)
    assert out.book.returning and len(out.book.scheduled) >= 1
    return out.book


def test_a_running_return_chain_ends_whole_and_waits_for_a_claim():
    book = chain_book()
    running = book.current.index
    out = book.interrupt(2.0, ExpireReason.OPERATOR_EXPIRE)
    (event,) = out.events
    assert (event.expired, event.reason, event.holder) == (running, ExpireReason.OPERATOR_EXPIRE, Holder.OPERATOR)
    cur = out.book.current
    assert cur.holder is Holder.OPERATOR and not cur.claimed  # AWAITING_CLAIM: nobody drives until a claim
    assert all(lease.chain != book.current.chain for lease in out.book.scheduled)  # the rest of the chain is gone


def test_a_claimed_operator_lease_ends_too_so_commands_from_before_are_stale():
    book = LeaseBook().acquire(255, 190, 0.0).book
    out = book.interrupt(1.0, ExpireReason.STUCK)
    assert out.events and out.book.current.index > 0 and not out.book.current.claimed
    assert out.book.check(255).reason is not None  # the operator's old lease no longer executes


def test_nothing_to_end_is_no_event():
    assert not LeaseBook().interrupt(1.0, ExpireReason.STUCK).events
    book = LeaseBook().acquire(255, 190, 0.0).book.interrupt(1.0, ExpireReason.STUCK).book
    assert not book.interrupt(2.0, ExpireReason.STUCK).events  # already awaiting a claim
