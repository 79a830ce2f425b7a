"""The lease rules, walked through the patent's own examples (US 2022/0197292, FIG. 2-3 and claims 1-6)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from vehicle.lease import (
    ExpireReason,
    Holder,
    LeaseBook,
    LeaseConfig,
    LeaseEvent,
    LeaseId,
    QueuedCommand,
    RejectReason,
    ServiceBlock,
    Verdict,
)
from vehicle.lease_root import owner_stale

GCS, OTHER = 255, 245


def acquired(t: float = 0.0, **cfg) -> LeaseBook:
    out = LeaseBook(config=LeaseConfig(**cfg)).acquire(GCS, 190, t, seed=7)
    return out.book


def test_lease_id_prints_orders_and_divides():
    a0 = LeaseId(5, (0,))
    assert str(a0) == "[5,0]"
    assert str(a0.child(0).child(3)) == "[5,0,0,3]"
    assert LeaseId(5, (1,)).newer_than(a0)
    assert LeaseId(5, (0, 2)).newer_than(LeaseId(5, (0, 1)))
    assert a0.is_ancestor_of(a0.child(4))
    assert LeaseId.parse("[5,1,0,2]") == LeaseId(5, (1, 0, 2))
    with pytest.raises(ValueError):
        LeaseId(5, (0,)).newer_than(LeaseId(6, (0,)))


def test_fig2a_root_creates_operator_lease_and_schedules_return():
    """FIG. 2A: acquiring the root [A] creates [A,0] for the operator; the return lease [A,1] waits behind it."""
    book = acquired()
    assert book.owner == GCS and book.epoch is not None
    assert book.current.index == 0 and book.current.holder is Holder.OPERATOR and book.current.claimed
    assert [x.index for x in book.scheduled] == [1]
    assert book.scheduled[0].holder is Holder.RETURN_SERVICE
    assert book.check(GCS).verdict is Verdict.EXECUTE  # implicit: the sender's last claimed lease


def test_fig2b_comms_lost_hands_the_vehicle_to_the_return_lease():
    """FIG. 2B: [A,0] expires when the link is silent past the timeout; [A,1] becomes current."""
    book = acquired(link_timeout=3.0)
    book = book.heard(GCS, 1.0)
    assert book.tick(3.99).events == ()
    out = book.tick(4.0)  # first tick at or after LNK_TIMEOUT of silence
    (ev,) = out.events
    assert (ev.expired, ev.current, ev.reason, ev.holder) == (0, 1, ExpireReason.COMMS_LOST, Holder.RETURN_SERVICE)
    assert out.book.current.index == 1
    # the operator's teleop under [A,0] is now a stale command
    chk = out.book.check(GCS)
    assert chk.verdict is Verdict.REJECT and chk.reason is RejectReason.EXPIRED
    # and COMMS_LOST does not fire again for the same silence
    assert out.book.tick(10.0).events == ()


def test_fig2c_newer_lease_expires_every_lower_one():
    """FIG. 2C: the operator claims a lease above every existing one: all lower leases expire."""
    book = acquired()
    epoch = book.epoch
    out, chk = book.claim(GCS, epoch, 0, 1.0)
    assert chk.executes and chk.lease == LeaseId(epoch, (2,))
    (ev,) = out.events
    assert (ev.expired, ev.current, ev.reason) == (0, 2, ExpireReason.NEWER_LEASE)
    # re-armed: the return plan is scheduled behind the new operator lease
    assert [x.index for x in out.book.scheduled] == [3]
    assert out.book.check(GCS, LeaseId(epoch, (0,))).reason is RejectReason.EXPIRED
    assert out.book.check(GCS, LeaseId(epoch, (2,))).executes


def test_fig3_return_service_navigates_under_subleases():
    """FIG. 3: [A,0] teleop, [A,1] handed to the return service, its navigation under [A,1,0,N]."""
    book = acquired()
    e = book.epoch
    assert book.check(GCS, LeaseId(e, (0, 0))).executes  # teleop under [A,0,0]
    out = book.tick(3.0)
    book = out.book
    block = LeaseId(e, (1,))
    book, b0 = book.issue_sublease(block)
    assert b0 == LeaseId(e, (1, 0))
    book, seg0 = book.issue_sublease(b0)
    book, seg1 = book.issue_sublease(b0)
    assert (seg0, seg1) == (LeaseId(e, (1, 0, 0)), LeaseId(e, (1, 0, 1)))
    # a replan supersedes the older segment: its commands are dropped
    assert book.check(GCS, seg1).executes
    older = book.check(GCS, seg0)
    assert older.verdict is Verdict.REJECT and older.reason is RejectReason.EXPIRED


def test_claim1_only_the_current_lease_executes():
    book = acquired()
    e = book.epoch
    assert book.check(GCS, LeaseId(e, (0,))).verdict is Verdict.EXECUTE
    assert book.check(GCS, LeaseId(e, (1,))).verdict is Verdict.QUEUE
    assert book.check(GCS, LeaseId(e, (9,))).reason is RejectReason.INVALID
    assert book.check(OTHER, LeaseId(e, (0,))).reason is RejectReason.NOT_IN_CONTROL
    assert book.check(GCS, LeaseId((e + 1) & 0xFFFF, (0,))).reason is RejectReason.WRONG_EPOCH


def test_claim2_queued_commands_run_when_their_lease_becomes_current():
    book = acquired()
    e = book.epoch
    book = book.enqueue(QueuedCommand(LeaseId(e, (1,)), GCS, "a"))
    book = book.enqueue(QueuedCommand(LeaseId(e, (1,)), GCS, "b"))
    out, _ = book.expire(GCS, e, 0, 2.0)
    assert [q.payload for q in out.released] == ["a", "b"]
    assert out.book.queue == ()


def test_claim3_explicit_expire_starts_the_return_without_a_loss():
    book = acquired()
    out, chk = book.expire(GCS, book.epoch, 0, 1.0)
    assert chk.executes
    (ev,) = out.events
    assert ev.reason is ExpireReason.OPERATOR_EXPIRE and out.book.current.holder is Holder.RETURN_SERVICE
    # the link never went down, so hearing the operator does not halt this return
    b = out.book
    for k in range(20):
        b = b.heard(GCS, 1.0 + 0.2 * k)
        assert b.tick(1.0 + 0.2 * k).events == ()
    # only the current lease can be expired
    _, chk2 = out.book.expire(GCS, out.book.epoch, 0, 2.0)
    assert chk2.reason is RejectReason.EXPIRED


def test_claim4_link_regained_ends_the_chain_and_waits_for_a_claim():
    blocks = (ServiceBlock("rtl"), ServiceBlock("hold"), ServiceBlock("home"))
    book = LeaseBook(config=LeaseConfig(), plan=blocks).acquire(GCS, 190, 0.0).book
    book = book.tick(3.0).book  # COMMS_LOST -> [E,1] return
    assert book.current.block.payload == "rtl"
    book = book.heard(GCS, 10.0).heard(GCS, 10.5)
    assert book.tick(10.5).events == ()  # heard for 0.5 s only
    book = book.heard(GCS, 11.0)
    out = book.tick(11.0)
    (ev,) = out.events
    assert ev.reason is ExpireReason.LINK_REGAINED and ev.expired == 1
    cur = out.book.current
    assert cur.holder is Holder.OPERATOR and not cur.claimed
    assert cur.index == 4  # [E,2] hold and [E,3] home expired with the chain
    # the vehicle holds: the operator's old lease is stale until it claims the fresh one
    assert out.book.check(GCS).reason is RejectReason.EXPIRED
    # re-armed behind the unclaimed lease, because the link is up
    assert [x.block.payload for x in out.book.scheduled] == ["rtl", "hold", "home"]
    out2, chk = out.book.claim(GCS, out.book.epoch, -1, 12.0)
    assert chk.executes and chk.lease.index == 4 and out2.events == ()
    assert out2.book.check(GCS).executes


def test_claim5_fallback_chain_runs_block_by_block_then_holds_unarmed():
    blocks = (ServiceBlock("rtl"), ServiceBlock("hold"))
    book = LeaseBook(plan=blocks).acquire(GCS, 190, 0.0).book
    book = book.tick(3.0).book
    reasons = []
    for reason in (ExpireReason.COMPLETED, ExpireReason.TIMEOUT):
        out = book.finish(book.current.index, reason, 10.0)
        reasons.append(out.events[0].reason)
        book = out.book
    assert reasons == [ExpireReason.COMPLETED, ExpireReason.TIMEOUT]
    assert book.current.holder is Holder.OPERATOR and not book.current.claimed
    assert book.scheduled == ()  # never armed while the link is down
    assert book.finish(book.current.index, ExpireReason.COMPLETED, 11.0).events == ()


def test_claim6_handover_to_a_new_root_expires_the_old_epoch():
    book = acquired(stale_take=True)
    old_epoch = book.epoch
    assert book.admit(OTHER, 190, 1.0).book.owner == GCS  # owner is fresh: no takeover
    out = book.admit(OTHER, 190, 5.0)  # owner silent past LNK_TIMEOUT
    (ev,) = out.events
    assert ev.reason is ExpireReason.ROOT_REPLACED and out.book.owner == OTHER
    assert out.book.epoch != old_epoch
    assert out.book.check(GCS).reason is RejectReason.NOT_IN_CONTROL
    out2, chk = out.book.expire(OTHER, old_epoch, 0, 5.5)
    assert chk.reason is RejectReason.WRONG_EPOCH and out2.events == ()


def test_no_stale_takeover_when_disabled():
    book = acquired(stale_take=False)
    assert book.admit(OTHER, 190, 50.0).book.owner == GCS


def test_autogrant_off_needs_explicit_acquire():
    book = LeaseBook(config=LeaseConfig(autogrant=False))
    assert book.admit(GCS, 190, 0.0).book.owner is None


def test_no_plan_means_hold_after_comms_lost():
    book = LeaseBook(plan=()).acquire(GCS, 190, 0.0).book
    out = book.tick(3.0)
    (ev,) = out.events
    assert ev.holder is Holder.OPERATOR and not out.book.current.claimed


def test_rearm_off_leaves_the_operator_unprotected_after_a_chain():
    book = acquired(rearm=False)
    book = book.tick(3.0).book
    book = book.finish(1, ExpireReason.COMPLETED, 9.0).book
    book = book.heard(GCS, 10.0).heard(GCS, 11.0)
    book = book.tick(11.0).book
    assert book.scheduled == ()


def test_release_drops_the_queue_and_the_owner():
    book = acquired()
    book = book.enqueue(QueuedCommand(LeaseId(book.epoch, (1,)), GCS, ("cmd", 1)))
    book = book.heard(GCS, 0.5)
    out = book.release(GCS, 1.0)
    assert out.book.owner is None and out.events[0].reason is ExpireReason.RELEASED
    assert len(out.dropped) == 1
    assert out.book.check(GCS).reason is RejectReason.NOT_IN_CONTROL


def test_new_epoch_differs_from_previous():
    book = acquired()
    for k in range(50):
        nxt = book.acquire(GCS, 190, float(k), seed=k).book
        assert nxt.epoch != book.epoch and nxt.epoch != 0
        book = nxt


def test_a_running_return_is_never_taken_over_and_a_silent_owner_after_it_is():
    """docs/architecture.md §3.8, as a timeline: the owner falls silent at 0 s; from 3 s the return holds the lease, and
    no other station takes the root, neither explicitly nor by auto-grant, even though the owner is stale; once the
    chain has ended (AWAITING_CLAIM) the silent owner may be taken over."""
    book = LeaseBook(config=LeaseConfig(link_timeout=3.0, stale_take=True)).acquire(GCS, 190, 0.0, seed=7).book
    assert book.take_refusal(OTHER, 1.0) == f"owned by GCS {GCS}; takeover not allowed"  # owner still fresh
    book = book.tick(3.0).book  # COMMS_LOST: the return service holds the lease
    assert book.returning and owner_stale(book, 4.0)
    for t in (3.0, 4.0, 30.0):
        assert book.take_refusal(OTHER, t) == "return in progress"
        out = book.admit(OTHER, 190, t)
        assert out.book is book and out.events == ()
        chk = book.check(OTHER)
        assert chk.reason is RejectReason.NOT_IN_CONTROL and chk.detail == "return in progress"
    allowed = replace(book, takeover_allowed=True)  # not even a takeover the owner once allowed
    assert allowed.take_refusal(OTHER, 4.0) == "return in progress"
    book = book.finish(book.current.index, ExpireReason.COMPLETED, 31.0).book  # the chain ran out
    assert not book.returning and book.current.holder is Holder.OPERATOR and not book.current.claimed
    assert book.take_refusal(OTHER, 31.0) is None
    out = book.admit(OTHER, 190, 31.0)
    assert out.book.owner == OTHER and out.events[0].reason is ExpireReason.ROOT_REPLACED
    assert book.owner == GCS  # and the owner could always have come back itself
    assert book.take_refusal(GCS, 4.0) is None


def test_every_lease_statustext_fits_one_chunk():
    """A lease event is announced in one STATUSTEXT (50 characters): a two-chunk text arrives in pieces."""
    for epoch in (1, 65535):
        for expired in (None, 0, 65534):
            for current in (None, 0, 65534):
                for reason in ExpireReason:
                    for holder in Holder:
                        text = LeaseEvent(0.0, epoch, expired, current, reason, holder).describe()
                        assert len(text.encode()) <= 50, text
