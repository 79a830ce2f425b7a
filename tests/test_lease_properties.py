"""Property-based tests: random sequences of everything a ground station, the link and the return service can do
to the lease book, checked against the invariants of docs/architecture.md §3 and an independent model of the owner's
link."""

from __future__ import annotations

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from vehicle.lease import (
    ExpireReason,
    Holder,
    LeaseBook,
    LeaseConfig,
    LeaseId,
    LeaseState,
    Outcome,
    QueuedCommand,
    ServiceBlock,
    Verdict,
)

STATIONS = (255, 245, 200)
TIMEOUT, REGAIN, GAP = 3.0, 1.0, 1.5
EPS = 1e-6  # deadlines are met within this (float sums of steps must not fire a tick late)


class LeaseMachine(RuleBasedStateMachine):
    @initialize(rearm=st.booleans(), stale_take=st.booleans(), blocks=st.integers(0, 3))
    def start(self, rearm: bool, stale_take: bool, blocks: int) -> None:
        cfg = LeaseConfig(link_timeout=TIMEOUT, regain_s=REGAIN, contact_gap=GAP, rearm=rearm, stale_take=stale_take)
        self.book = LeaseBook(config=cfg, plan=tuple(ServiceBlock(f"b{k}") for k in range(blocks)))
        self.t = 0.0
        self.dead: set[LeaseId] = set()  # every execution lease that ever expired, by epoch
        self.old_epochs: set[int] = set()
        self.enqueued: list[QueuedCommand] = []
        # independent model of the owner link
        self.m_last: float | None = None
        self.m_since: float | None = None
        self.m_lost = False
        self.comms_lost_in_episode = 0

    # ----- helpers -----------------------------------------------------------------------------------------
    def apply(self, out: Outcome) -> None:
        before, after = self.book, out.book
        changed = (before.epoch, before.current.index if before.current else None) != (
            after.epoch, after.current.index if after.current else None)
        assert len(out.events) == (1 if changed else 0), (before.current, after.current, out.events)
        for ev in out.events:
            if ev.expired is not None and before.epoch is not None:
                self.dead.add(LeaseId(before.epoch, (ev.expired,)))
            assert ev.current == (after.current.index if after.current else None)
            if before.epoch is not None and before.epoch != after.epoch:
                self.old_epochs.add(before.epoch)
                # every lease of the old epoch is gone
                for lease in before.leases:
                    self.dead.add(LeaseId(before.epoch, (lease.index,)))
            if ev.reason is ExpireReason.COMMS_LOST:
                self.comms_lost_in_episode += 1
                assert self.comms_lost_in_episode == 1, "COMMS_LOST fired twice in one loss"
        # a lease that was scheduled and is gone without ever being current is dead too
        if after.epoch == before.epoch and before.epoch is not None:
            live = {x.index for x in after.leases}
            for x in before.leases:
                if x.index not in live:
                    self.dead.add(LeaseId(before.epoch, (x.index,)))
        # queued commands are released only under their own lease, in the order they were queued
        for q in out.released:
            assert after.current is not None and q.lease.path[0] == after.current.index
            assert q.lease.epoch == after.epoch
        released = list(out.released)
        if released:
            mine = [q for q in self.enqueued if q in released]
            assert mine == released
        for q in (*out.released, *out.dropped):
            if q in self.enqueued:
                self.enqueued.remove(q)
        if before.owner != after.owner or before.epoch != after.epoch:
            self._reset_link_model(after)
            # docs/architecture.md §3.8: a running return is never taken over by another station
            assert after.owner is None or before.owner in (None, after.owner) or not before.returning
        self.book = after

    def _reset_link_model(self, book: LeaseBook) -> None:
        self.m_last = book.link.last_heard
        self.m_since = book.link.contact_since
        self.m_lost = False
        self.comms_lost_in_episode = 0

    # ----- rules -------------------------------------------------------------------------------------------
    @rule(station=st.sampled_from(STATIONS), seed=st.integers(0, 10_000))
    def acquire(self, station: int, seed: int) -> None:
        if self.book.take_refusal(station, self.t) is None:
            self.apply(self.book.acquire(station, 190, self.t, seed))

    @rule(station=st.sampled_from(STATIONS))
    def admit(self, station: int) -> None:
        self.apply(self.book.admit(station, 190, self.t))

    @rule(station=st.sampled_from(STATIONS))
    def release(self, station: int) -> None:
        self.apply(self.book.release(station, self.t))

    @rule(station=st.sampled_from(STATIONS), index=st.integers(-1, 12))
    def claim(self, station: int, index: int) -> None:
        epoch = self.book.epoch if self.book.epoch is not None else 1
        out, chk = self.book.claim(station, epoch, index, self.t)
        if not chk.executes:
            assert out.book == self.book
        self.apply(out)

    @rule(station=st.sampled_from(STATIONS), offset=st.integers(-2, 2), stale_epoch=st.booleans())
    def expire(self, station: int, offset: int, stale_epoch: bool) -> None:
        if self.book.epoch is None:
            return
        epoch = next(iter(self.old_epochs)) if stale_epoch and self.old_epochs else self.book.epoch
        out, chk = self.book.expire(station, epoch, max(0, self.book.current.index + offset), self.t)
        if not chk.executes:
            assert out.book == self.book
        self.apply(out)

    @rule(station=st.sampled_from(STATIONS))
    def rtl(self, station: int) -> None:
        self.apply(self.book.expire_current(station, self.t)[0])

    @rule(reason=st.sampled_from([ExpireReason.COMPLETED, ExpireReason.TIMEOUT, ExpireReason.STUCK]))
    def service_finishes(self, reason: ExpireReason) -> None:
        if self.book.current is not None:
            self.apply(self.book.finish(self.book.current.index, reason, self.t))

    @rule(blocks=st.integers(0, 3))
    def upload_plan(self, blocks: int) -> None:
        self.apply(self.book.schedule_plan([ServiceBlock(f"p{k}") for k in range(blocks)], self.t))

    @precondition(lambda self: self.book.current is not None and self.book.current.holder is Holder.RETURN_SERVICE)
    @rule(depth=st.integers(0, 1))
    def replan(self, depth: int) -> None:
        cur = self.book.current_id
        parent = cur if depth == 0 or not self.book.current.newest_sub else cur.child(self.book.current.newest_sub[0])
        before = self.book.current.newest_sub
        self.book, child = self.book.issue_sublease(parent)
        if before[: len(child.sub)] and len(before) >= len(child.sub):
            assert child.sub > before[: len(child.sub)]
        assert self.book.check(self.book.owner, child).executes

    @rule(station=st.sampled_from(STATIONS), which=st.sampled_from(["implicit", "current", "dead", "next", "sub"]),
          payload=st.integers())
    def command(self, station: int, which: str, payload: int) -> None:
        book = self.book
        claim: LeaseId | None = None
        if which == "current":
            claim = book.current_id
        elif which == "dead" and self.dead:
            claim = sorted(self.dead, key=lambda x: (x.epoch, x.path))[payload % len(self.dead)]
        elif which == "next" and book.scheduled:
            claim = LeaseId(book.epoch, (book.scheduled[payload % len(book.scheduled)].index,))
        elif which == "sub" and book.current_id is not None:
            claim = book.current_id.child(payload % 3)
        chk = book.check(station, claim)
        effective = claim if claim is not None else book.claimed_by(station)
        if chk.verdict is Verdict.EXECUTE:
            assert station == book.owner
            assert effective is not None
            assert effective.epoch not in self.old_epochs
            assert LeaseId(effective.epoch, effective.path[:1]) not in self.dead, f"{effective} expired"
            assert effective.path[0] == book.current.index
        if chk.verdict is Verdict.QUEUE:
            q = QueuedCommand(claim, station, payload)
            self.book = book.enqueue(q)
            self.enqueued.append(q)

    @rule(station=st.sampled_from(STATIONS), dt=st.sampled_from([0.1, 0.5, 1.0]))
    def message(self, station: int, dt: float) -> None:
        self.t += dt
        self._tick()
        if station == self.book.owner:
            continuous = self.m_since is not None and self.m_last is not None and self.t - self.m_last <= GAP + EPS
            self.m_since = self.m_since if continuous else self.t
            self.m_last = self.t
        self.book = self.book.heard(station, self.t)

    @rule(dt=st.sampled_from([0.02, 0.5, 1.0, 2.9, 3.0, 7.0]))
    def time_passes(self, dt: float) -> None:
        self.t += dt
        self._tick()

    def _tick(self) -> None:
        book = self.book
        # independent oracle for the link triggers
        expect_lost_now = False
        if (book.owner is not None and not self.m_lost and self.m_last is not None
                and self.t - self.m_last >= TIMEOUT - EPS):
            self.m_lost = True
            self.m_since = None  # contact from before the loss never counts as regained contact
            self.comms_lost_in_episode = 0
            expect_lost_now = book.current.holder is Holder.OPERATOR
        elif (book.owner is not None and self.m_lost and self.m_last is not None and self.t - self.m_last <= GAP + EPS
              and self.m_since is not None and self.t - self.m_since >= REGAIN - EPS):
            self.m_lost = False
        out = book.tick(self.t)
        reasons = [e.reason for e in out.events]
        assert (ExpireReason.COMMS_LOST in reasons) == expect_lost_now, (reasons, expect_lost_now)
        assert out.book.link.lost == self.m_lost
        if ExpireReason.LINK_REGAINED in reasons:
            assert book.link.lost and not self.m_lost
        self.apply(out)

    # ----- invariants --------------------------------------------------------------------------------------
    @invariant()
    def exactly_one_current_while_rooted(self) -> None:
        book = self.book
        if book.owner is None:
            assert book.leases == () and book.epoch is None
            return
        states = [x.state for x in book.leases]
        assert states[0] is LeaseState.CURRENT
        assert all(s is LeaseState.SCHEDULED for s in states[1:])
        idx = [x.index for x in book.leases]
        assert idx == sorted(set(idx)) and idx[-1] < book.next_index

    @invariant()
    def plan_never_armed_while_link_down(self) -> None:
        book = self.book
        if book.owner is not None and book.link.lost and book.current.holder is Holder.OPERATOR:
            assert book.scheduled == () or all(x.chain <= book.chains for x in book.scheduled)

    @invariant()
    def queue_only_holds_scheduled_leases(self) -> None:
        live = {x.index for x in self.book.scheduled}
        for q in self.book.queue:
            assert q.lease.epoch == self.book.epoch and q.lease.path[0] in live


TestLeaseMachine = LeaseMachine.TestCase
TestLeaseMachine.settings = settings(
    max_examples=2500, stateful_step_count=40, deadline=None, suppress_health_check=list(HealthCheck),
    print_blob=True,
)
