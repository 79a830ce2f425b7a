"""Leases: who may command the vehicle, and what happens when that right expires (DESIGN §3).

A pure state machine in the style of the Spot SDK's ``lease.py`` and PX4's failsafe framework: every value here is
immutable, every transition is a method that takes the time as an argument and returns a new ``LeaseBook`` plus
what happened (``Outcome``). No clock, socket or MAVLink framing lives in this file, so the rules can be tested on
their own and replayed from a journal.

Vocabulary (patent US 2022/0197292): ``[E]`` is the root lease with epoch E, ``[E,i]`` execution lease i, and
``[E,i,j,...]`` its subleases. The *current* execution lease is the lowest-index lease that has not expired.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

from vehicle.frozen import evolve
from vehicle.link_watch import EPS, Delivery, LinkWatch, Trigger, WatchConfig

_NO_TRIGGER = Trigger.NONE  # (read every tick: an enum member through its class costs more than a function call)

NO_INDEX = 0xFFFF  # wire value for "no lease" in LEASE_EVENT / LEASE_STATUS
RETURN_IN_PROGRESS = "return in progress"  # why a takeover (or a stranger's command) is refused during a return


class Holder(enum.IntEnum):
    """LEASE_HOLDER."""

    NONE = 0
    OPERATOR = 1
    RETURN_SERVICE = 2


class LeaseState(enum.IntEnum):
    SCHEDULED = 0
    CURRENT = 1
    EXPIRED = 2


class ExpireReason(enum.IntEnum):
    """LEASE_EXPIRE_REASON: the expiration triggers of DESIGN §3.5."""

    NONE = 0
    COMMS_LOST = 1
    OPERATOR_EXPIRE = 2
    NEWER_LEASE = 3
    COMPLETED = 4
    LINK_REGAINED = 5
    TIMEOUT = 6
    STUCK = 7
    ROOT_REPLACED = 8
    RELEASED = 9


class Verdict(enum.Enum):
    EXECUTE = "execute"
    QUEUE = "queue"
    REJECT = "reject"


# ``check`` runs for every command and on ticks a teleop setpoint is judged: its accepting path compares against
# these module-level names (an enum member read through its class costs more than a function call)
_EXECUTE, _OPERATOR = Verdict.EXECUTE, Holder.OPERATOR


class RejectReason(enum.Enum):
    NOT_IN_CONTROL = "not in control"
    WRONG_EPOCH = "wrong epoch"
    EXPIRED = "expired lease"
    INVALID = "invalid lease"


@dataclass(frozen=True, order=True)
class LeaseId:
    """``[E,i,j,...]``: an epoch and a path of sequence numbers (empty path = the root lease)."""

    epoch: int
    path: tuple[int, ...] = ()

    @property
    def index(self) -> int:
        """Execution-lease index i; the root has none."""
        if not self.path:
            raise ValueError(f"{self} is a root lease and has no execution index")
        return self.path[0]

    @property
    def sub(self) -> tuple[int, ...]:
        """The sublease part below the execution lease: ``(j, ...)``."""
        return self.path[1:]

    def child(self, n: int) -> LeaseId:
        return LeaseId(self.epoch, (*self.path, n))

    def is_ancestor_of(self, other: LeaseId) -> bool:
        """True for the same lease or one it was divided from."""
        return self.epoch == other.epoch and other.path[: len(self.path)] == self.path

    def newer_than(self, other: LeaseId) -> bool:
        """Within one epoch, a later sequence is newer; leases of different epochs are not ordered."""
        if self.epoch != other.epoch:
            raise ValueError(f"{self} and {other} belong to different epochs")
        return self.path > other.path

    def __str__(self) -> str:
        return "[" + ",".join(str(x) for x in (self.epoch, *self.path)) + "]"

    @classmethod
    def parse(cls, text: str) -> LeaseId:
        parts = [int(p) for p in text.strip().strip("[]").split(",") if p.strip()]
        if not parts:
            raise ValueError(f"not a lease id: {text!r}")
        return cls(parts[0], tuple(parts[1:]))


@dataclass(frozen=True)
class ServiceBlock:
    """One block of the return plan as the lease rules see it; ``payload`` is the planner's business."""

    payload: Any = None
    halt_on_regain: bool = True


@dataclass(frozen=True)
class ExecutionLease:
    index: int
    holder: Holder
    state: LeaseState
    block: ServiceBlock | None = None
    claimed: bool = True
    chain: int = 0  # leases of one scheduled return plan share a chain number
    newest_sub: tuple[int, ...] = ()  # newest sublease path issued under this lease
    started_at: float | None = None


@dataclass(frozen=True)
class QueuedCommand:
    """A command sent under a SCHEDULED lease, held until that lease becomes current."""

    lease: LeaseId
    sender: int
    payload: Any


@dataclass(frozen=True)
class LeaseEvent:
    """Exactly one per transition: logged, journalled and sent as LEASE_EVENT + STATUSTEXT."""

    t: float
    epoch: int
    expired: int | None
    current: int | None
    reason: ExpireReason
    holder: Holder

    def describe(self) -> str:
        """The STATUSTEXT line: at most 50 characters for every epoch, index, reason and holder, so it travels in
        one STATUSTEXT without chunks (a chunked text arrives in pieces, and a lost piece garbles it)."""
        exp = "-" if self.expired is None else str(self.expired)
        cur = "-" if self.current is None else str(self.current)
        return f"lease {self.epoch}: {exp}->{cur} {self.reason.name} {_HOLDER_WORD[self.holder]}"


# who holds the new current lease, in a word short enough for one STATUSTEXT
_HOLDER_WORD = {Holder.NONE: "none", Holder.OPERATOR: "operator", Holder.RETURN_SERVICE: "return"}


@dataclass(frozen=True)
class LeaseConfig:
    """The parameters the rules depend on (LNK_*, RTL_REARM, LEASE_*)."""

    link_timeout: float = 3.0  # LNK_TIMEOUT
    regain_s: float = 1.0  # LNK_REGAIN_S
    contact_gap: float = 1.5  # LNK_GOOD_S: longest gap between messages that still counts as continuous contact
    min_quality: float = 0.25  # LNK_MIN_Q: owner's delivery below this for link_timeout is lost too (0 = silence only)
    rearm: bool = True  # RTL_REARM
    autogrant: bool = True  # LEASE_AUTOGRANT
    stale_take: bool = True  # LEASE_STALE_TAKE

    @property
    def watch(self) -> WatchConfig:
        """The part of the configuration the owner's link watch works with."""
        return WatchConfig(timeout=self.link_timeout, regain_s=self.regain_s, contact_gap=self.contact_gap,
                           min_quality=self.min_quality)


class Outcome(NamedTuple):
    """The result of a transition: the new book, its events and any queued commands released or dropped.

    A named tuple rather than a frozen dataclass: the lease tick answers one every 20 ms (nearly always "the
    same book, nothing happened"), and a tuple is built at a third of the cost, with the same names."""

    book: LeaseBook
    events: tuple[LeaseEvent, ...] = ()
    released: tuple[QueuedCommand, ...] = ()
    dropped: tuple[QueuedCommand, ...] = ()


@dataclass(frozen=True)
class Check:
    """An enforcement verdict for one command."""

    verdict: Verdict
    lease: LeaseId | None = None
    reason: RejectReason | None = None
    detail: str = ""

    @property
    def executes(self) -> bool:
        return self.verdict is Verdict.EXECUTE


def _epoch_after(previous: int | None, seed: int) -> int:
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
        age = self.link.age(t)
        return age is None or age >= self.config.link_timeout - EPS

    # ----- enforcement (pure reads, the hot path) ----------------------------------------------------------
    def check(self, sender: int, claim: LeaseId | None = None) -> Check:
        """Verdict for a state-changing command from ``sender`` carrying ``claim``.

        ``claim`` None means a standard message with no lease field: it is checked against the lease the
        sender last claimed (DESIGN §3.4).
        """
        if self.owner is None or sender != self.owner:
            why = RETURN_IN_PROGRESS if self.returning else "sender does not own the vehicle"
            return Check(Verdict.REJECT, claim, RejectReason.NOT_IN_CONTROL, why)
        if claim is None:
            claim = self.claimed_by(sender)
            if claim is None:
                return Check(Verdict.REJECT, None, RejectReason.EXPIRED, "no lease claimed")
        cur = self.leases[0]
        if claim.epoch != self.epoch:
            return Check(Verdict.REJECT, claim, RejectReason.WRONG_EPOCH, f"epoch {claim.epoch} is not {self.epoch}")
        if not claim.path:
            return Check(Verdict.REJECT, claim, RejectReason.INVALID, "a root lease carries no commands")
        index = claim.path[0]
        if index < cur.index:
            return Check(Verdict.REJECT, claim, RejectReason.EXPIRED,
                         f"{claim} expired; current is [{self.epoch},{cur.index}]")
        if index == cur.index:
            if cur.holder is _OPERATOR and not cur.claimed:
                return Check(Verdict.REJECT, claim, RejectReason.EXPIRED, f"{claim} is not claimed yet")
            sub = claim.path[1:]
            if sub and not _sub_is_live(sub, cur.newest_sub):
                return Check(Verdict.REJECT, claim, RejectReason.EXPIRED, f"sublease {claim} superseded")
            return Check(_EXECUTE, claim)
        if self.lease(index) is not None:
            return Check(Verdict.QUEUE, claim)
        return Check(Verdict.REJECT, claim, RejectReason.INVALID, f"{claim} does not exist; claim it first")

    # ----- root lease --------------------------------------------------------------------------------------
    def acquire(self, sysid: int, compid: int, t: float, seed: int = 0, allow_takeover: bool = False) -> Outcome:
        """A ground station takes the root: a fresh epoch E and the operator lease [E,0] (DESIGN §3.1)."""
        had_owner = self.owner is not None
        epoch = _epoch_after(self.last_epoch, seed)
        old_current = self.current.index if self.current else None
        dropped = self.queue
        book = replace(
            self, epoch=epoch, owner=sysid, owner_compid=compid, next_index=1, chains=0,
            leases=(ExecutionLease(0, Holder.OPERATOR, LeaseState.CURRENT, started_at=t),),
            claims=((sysid, LeaseId(epoch, (0,))),), queue=(), link=LinkWatch(self.config.watch).heard(t),
            takeover_allowed=allow_takeover, last_epoch=epoch,
            last_reason=ExpireReason.ROOT_REPLACED if had_owner else self.last_reason,
        )
        book = book._arm(t)
        reason = ExpireReason.ROOT_REPLACED if had_owner else ExpireReason.NONE
        event = LeaseEvent(t, epoch, old_current, 0, reason, Holder.OPERATOR)
        return Outcome(book, (event,), dropped=dropped)

    def release(self, sysid: int, t: float) -> Outcome:
        """The owner gives the vehicle up: every lease expires and nobody owns it."""
        if sysid != self.owner:
            return Outcome(self)
        old = self.current.index if self.current else None
        book = replace(self, epoch=None, owner=None, owner_compid=0, leases=(), claims=(), queue=(),
                       link=LinkWatch(self.config.watch), last_reason=ExpireReason.RELEASED,
                       takeover_allowed=False)
        event = LeaseEvent(t, self.epoch or 0, old, None, ExpireReason.RELEASED, Holder.NONE)
        return Outcome(book, (event,), dropped=self.queue)

    @property
    def returning(self) -> bool:
        """A service block of the return plan holds the current lease: the return is running."""
        return bool(self.leases) and self.leases[0].holder is Holder.RETURN_SERVICE

    def take_refusal(self, sysid: int, t: float) -> str | None:
        """Why ``sysid`` may not take the root now, or None if it may (unowned, its own, allowed takeover, or
        a stale owner).

        A running return is never taken over (DESIGN §3.8): the owner is silent exactly because its link is lost,
        which is what the return exists to protect, so a silent owner only becomes fair game once the chain has
        ended (AWAITING_CLAIM)."""
        if self.owner is None or self.owner == sysid:
            return None
        if self.returning:
            return RETURN_IN_PROGRESS
        if self.takeover_allowed or (self.config.stale_take and self.owner_stale(t)):
            return None
        return f"owned by GCS {self.owner}; takeover not allowed"

    def may_take(self, sysid: int, t: float) -> bool:
        """Whether ``sysid`` may take the root now (see ``take_refusal``)."""
        return self.take_refusal(sysid, t) is None

    def admit(self, sender: int, compid: int, t: float, seed: int = 0) -> Outcome:
        """Plain clients (DESIGN §3.8): a state-changing command from a ground station that may take the
        vehicle implicitly acquires the root when auto-grant is on. Returns the book unchanged otherwise.
        An explicit allow-takeover is for REQUEST_OPERATOR_CONTROL only: a stream of commands never takes over."""
        if sender == self.owner or not self.config.autogrant:
            return Outcome(self)
        if self.owner is None or (not self.returning and self.config.stale_take and self.owner_stale(t)):
            return self.acquire(sender, compid, t, seed)
        return Outcome(self)

    # ----- owner link --------------------------------------------------------------------------------------
    def heard(self, sysid: int, t: float, seq: int | None = None) -> LeaseBook:
        """A message from the owner (MAVLink sequence number ``seq``) keeps the lease alive; the link watch
        measures its delivery, and ``tick`` evaluates the triggers."""
        if sysid != self.owner:
            return self
        return evolve(self, link=self.link.heard(t, seq))  # (every owner frame: the cheap copy)

    def tick(self, t: float) -> Outcome:
        """Consume the link watch's trigger: COMMS_LOST of an operator lease, LINK_REGAINED of a service block
        (DESIGN §3.5). The watch alone decides whether the link was lost or regained."""
        out = self.tick_changes(t)
        return Outcome(self) if out is None else out

    def tick_changes(self, t: float) -> Outcome | None:
        """``tick``, with None for "the same book, nothing happened": the answer of nearly every 20 ms tick, for
        which the vehicle loop then builds no ``Outcome``."""
        if self.owner is None:
            return None
        link, trigger = self.link.step(t)
        if trigger is _NO_TRIGGER:
            return None if link is self.link else Outcome(evolve(self, link=link))
        book = replace(self, link=link)
        cur = self.leases[0]
        if trigger is Trigger.LOST:
            if cur.holder is Holder.OPERATOR:
                return book._expire_current(t, ExpireReason.COMMS_LOST)
            return Outcome(book)
        if cur.holder is Holder.RETURN_SERVICE and cur.block is not None and cur.block.halt_on_regain:
            return book._end_chain(t, ExpireReason.LINK_REGAINED)
        return Outcome(book._arm(t))

    # ----- execution leases --------------------------------------------------------------------------------
    def claim(self, sysid: int, epoch: int, index: int, t: float) -> tuple[Outcome, Check]:
        """MAV_CMD_LEASE_CLAIM: -1 claims the current unclaimed operator lease ("resume by incrementing the
        lease"); any other index claims the next free index at or above it (NEWER_LEASE)."""
        if self.owner is None or sysid != self.owner:
            return Outcome(self), Check(Verdict.REJECT, None, RejectReason.NOT_IN_CONTROL, "not the owner")
        if epoch != self.epoch:
            return Outcome(self), Check(Verdict.REJECT, None, RejectReason.WRONG_EPOCH,
                                        f"epoch {epoch} is not {self.epoch}")
        cur = self.leases[0]
        if index < 0:
            if cur.holder is not Holder.OPERATOR or cur.claimed:
                return Outcome(self), Check(Verdict.REJECT, None, RejectReason.INVALID,
                                            "the current lease is not an unclaimed operator lease")
            lid = LeaseId(epoch, (cur.index,))
            leases = (replace(cur, claimed=True), *self.leases[1:])
            book = replace(self, leases=leases, claims=_set_claim(self.claims, sysid, lid))._arm(t)
            return Outcome(book), Check(Verdict.EXECUTE, lid)
        new_index = max(index, self.next_index)
        if new_index > NO_INDEX - 1:
            return Outcome(self), Check(Verdict.REJECT, None, RejectReason.INVALID, "lease index space exhausted")
        lid = LeaseId(epoch, (new_index,))
        fresh = ExecutionLease(new_index, Holder.OPERATOR, LeaseState.CURRENT, started_at=t)
        event = LeaseEvent(t, epoch, cur.index, new_index, ExpireReason.NEWER_LEASE, Holder.OPERATOR)
        book = replace(self, leases=(fresh,), next_index=new_index + 1, queue=(),
                       claims=_set_claim(self.claims, sysid, lid), last_reason=ExpireReason.NEWER_LEASE)
        return Outcome(book._arm(t), (event,), dropped=self.queue), Check(Verdict.EXECUTE, lid)

    def expire(self, sysid: int, epoch: int, index: int, t: float) -> tuple[Outcome, Check]:
        """MAV_CMD_LEASE_EXPIRE (or RTL): the explicit OPERATOR_EXPIRE trigger of the current lease."""
        chk = self.check(sysid, LeaseId(epoch, (index,)))
        if chk.verdict is Verdict.QUEUE:
            chk = Check(Verdict.REJECT, chk.lease, RejectReason.INVALID, "only the current lease can be expired")
        if not chk.executes and not (chk.reason is RejectReason.EXPIRED and self._is_unclaimed_current(index)):
            return Outcome(self), chk
        return self._expire_current(t, ExpireReason.OPERATOR_EXPIRE), Check(Verdict.EXECUTE, chk.lease)

    def expire_current(self, sysid: int, t: float) -> tuple[Outcome, Check]:
        """RTL button / RTL mode from a plain client: expire whatever the owner currently holds."""
        if self.owner is None or sysid != self.owner:
            return Outcome(self), Check(Verdict.REJECT, None, RejectReason.NOT_IN_CONTROL, "not the owner")
        if self.leases[0].holder is not Holder.OPERATOR:
            return Outcome(self), Check(Verdict.EXECUTE, self.current_id, detail="a return is already running")
        return self._expire_current(t, ExpireReason.OPERATOR_EXPIRE), Check(Verdict.EXECUTE, self.current_id)

    def finish(self, index: int, reason: ExpireReason, t: float) -> Outcome:
        """The auto-return service reports that its block ended: COMPLETED, TIMEOUT or STUCK."""
        if reason not in (ExpireReason.COMPLETED, ExpireReason.TIMEOUT, ExpireReason.STUCK):
            raise ValueError(f"{reason.name} is not a service completion")
        cur = self.current
        if cur is None or cur.index != index or cur.holder is not Holder.RETURN_SERVICE:
            return Outcome(self)
        return self._expire_current(t, reason)

    def interrupt(self, t: float, reason: ExpireReason) -> Outcome:
        """The robot was taken out of the book's hands from outside it (companion mode: the autopilot's pilot or its
        own failsafe changed mode, or the autopilot stopped answering): the current lease and everything scheduled
        behind it expire together, and a fresh operator lease waits, unclaimed, for the operator to resume
        (DESIGN §3.6). Nothing to end (no owner, or already awaiting a claim): the same book."""
        cur = self.current
        if self.owner is None or cur is None or (cur.holder is Holder.OPERATOR and not cur.claimed):
            return Outcome(self)
        out = replace(self, leases=(cur,), queue=())._expire_current(t, reason)
        return out._replace(dropped=self.queue + out.dropped)

    def issue_sublease(self, parent: LeaseId) -> tuple[LeaseBook, LeaseId]:
        """Divide the current lease: the new sublease supersedes every older one under ``parent``."""
        cur = self.current
        if cur is None or parent.epoch != self.epoch or not parent.path or parent.path[0] != cur.index:
            raise ValueError(f"{parent} is not the current lease")
        depth = len(parent.sub)
        newest = cur.newest_sub
        n = newest[depth] + 1 if len(newest) > depth and newest[:depth] == parent.sub else 0
        child = parent.child(n)
        leases = (replace(cur, newest_sub=child.sub), *self.leases[1:])
        return replace(self, leases=leases), child

    def schedule_plan(self, plan: Iterable[ServiceBlock], t: float, store: bool = True) -> Outcome:
        """Schedule a return plan behind the current operator lease. ``store`` (a mission upload) also makes it
        the plan re-armed from now on; without it (a one-off return, a plan started mid-way) the stored plan
        stays the one re-armed afterwards."""
        plan = tuple(plan)
        book = replace(self, plan=plan) if store else self
        if self.owner is None or self.leases[0].holder is not Holder.OPERATOR:
            return Outcome(book)
        kept = book.leases[:1]
        still_queued = tuple(q for q in book.queue if q.lease.path[0] == kept[0].index)
        gone = tuple(q for q in book.queue if q.lease.path[0] != kept[0].index)
        book = replace(book, leases=kept, queue=still_queued)
        return Outcome(book._arm(t, force=True, plan=plan), dropped=gone)

    def enqueue(self, command: QueuedCommand) -> LeaseBook:
        return replace(self, queue=(*self.queue, command))

    def with_config(self, config: LeaseConfig) -> LeaseBook:
        return replace(self, config=config, link=self.link.with_config(config.watch))

    # ----- internals ---------------------------------------------------------------------------------------
    def _is_unclaimed_current(self, index: int) -> bool:
        cur = self.current
        return cur is not None and cur.index == index and cur.holder is Holder.OPERATOR and not cur.claimed

    def _expire_current(self, t: float, reason: ExpireReason) -> Outcome:
        """The current lease expires; the next scheduled one (or a fresh unclaimed operator lease) is current."""
        cur = self.leases[0]
        rest = self.leases[1:]
        if rest:
            nxt = replace(rest[0], state=LeaseState.CURRENT, started_at=t)
            leases = (nxt, *rest[1:])
            next_index = self.next_index
        else:
            nxt = ExecutionLease(self.next_index, Holder.OPERATOR, LeaseState.CURRENT, claimed=False, started_at=t)
            leases = (nxt,)
            next_index = self.next_index + 1
        released = tuple(q for q in self.queue if q.lease.path[0] == nxt.index)
        queue = tuple(q for q in self.queue if q.lease.path[0] > nxt.index)
        dropped = tuple(q for q in self.queue if q.lease.path[0] < nxt.index)
        book = replace(self, leases=leases, next_index=next_index, queue=queue, last_reason=reason)
        event = LeaseEvent(t, self.epoch or 0, cur.index, nxt.index, reason, nxt.holder)
        return Outcome(book._arm(t), (event,), released, dropped)

    def _end_chain(self, t: float, reason: ExpireReason) -> Outcome:
        """LINK_REGAINED: the current block and the rest of its contingency chain expire together."""
        chain = self.leases[0].chain
        rest = tuple(lease for lease in self.leases[1:] if lease.chain != chain or lease.holder is Holder.OPERATOR)
        gone = {lease.index for lease in self.leases[1:]} - {lease.index for lease in rest}
        dropped = tuple(q for q in self.queue if q.lease.path[0] in gone)
        book = replace(self, leases=(self.leases[0], *rest),
                       queue=tuple(q for q in self.queue if q.lease.path[0] not in gone))
        out = book._expire_current(t, reason)
        return out._replace(dropped=dropped + out.dropped)

    def _arm(self, t: float, force: bool = False, plan: tuple[ServiceBlock, ...] | None = None) -> LeaseBook:
        """Re-arm (DESIGN §3.7): behind a current operator lease, with the link up, schedule the return plan
        (``plan``, or the stored one)."""
        plan = self.plan if plan is None else plan
        if self.owner is None or not self.leases or not plan:
            return self
        cur = self.leases[0]
        if cur.holder is not Holder.OPERATOR or len(self.leases) > 1 or self.link.lost:
            return self
        if not force and not self.config.rearm and (cur.index != 0 or not cur.claimed):
            return self
        chain = self.chains + 1
        blocks = tuple(
            ExecutionLease(self.next_index + k, Holder.RETURN_SERVICE, LeaseState.SCHEDULED, block=b, chain=chain)
            for k, b in enumerate(plan)
        )
        return replace(self, leases=(cur, *blocks), next_index=self.next_index + len(blocks), chains=chain)

    # ----- snapshot / restore ------------------------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        """A JSON-able picture of the book (block payloads must themselves be JSON-able)."""

        def lease(x: ExecutionLease) -> dict[str, Any]:
            return {
                "index": x.index, "holder": x.holder.name, "state": x.state.name, "claimed": x.claimed,
                "chain": x.chain, "newest_sub": list(x.newest_sub), "started_at": x.started_at,
                "block": None if x.block is None else {"payload": x.block.payload,
                                                       "halt_on_regain": x.block.halt_on_regain},
            }

        c = self.config
        return {
            "config": {"link_timeout": c.link_timeout, "regain_s": c.regain_s, "contact_gap": c.contact_gap,
                       "min_quality": c.min_quality, "rearm": c.rearm, "autogrant": c.autogrant,
                       "stale_take": c.stale_take},
            "epoch": self.epoch, "owner": self.owner, "owner_compid": self.owner_compid,
            "leases": [lease(x) for x in self.leases], "next_index": self.next_index, "chains": self.chains,
            "plan": [{"payload": b.payload, "halt_on_regain": b.halt_on_regain} for b in self.plan],
            "claims": [[s, lid.epoch, list(lid.path)] for s, lid in self.claims],
            "queue": [[q.lease.epoch, list(q.lease.path), q.sender, q.payload] for q in self.queue],
            "link": _link_snapshot(self.link),
            "last_reason": self.last_reason.name, "takeover_allowed": self.takeover_allowed,
            "last_epoch": self.last_epoch,
        }

    @classmethod
    def restore(cls, snap: dict[str, Any]) -> LeaseBook:
        def block(d: dict[str, Any] | None) -> ServiceBlock | None:
            return None if d is None else ServiceBlock(_freeze(d["payload"]), d["halt_on_regain"])

        leases = tuple(
            ExecutionLease(x["index"], Holder[x["holder"]], LeaseState[x["state"]], block(x["block"]),
                           x["claimed"], x["chain"], tuple(x["newest_sub"]), x["started_at"])
            for x in snap["leases"]
        )
        config = LeaseConfig(**snap["config"])
        return cls(
            config=config, epoch=snap["epoch"], owner=snap["owner"],
            owner_compid=snap["owner_compid"], leases=leases, next_index=snap["next_index"], chains=snap["chains"],
            plan=tuple(block(b) for b in snap["plan"]),  # type: ignore[misc]
            claims=tuple((s, LeaseId(e, tuple(p))) for s, e, p in snap["claims"]),
            queue=tuple(QueuedCommand(LeaseId(e, tuple(p)), s, _freeze(pl)) for e, p, s, pl in snap["queue"]),
            link=_link_restore(config.watch, snap["link"]), last_reason=ExpireReason[snap["last_reason"]],
            takeover_allowed=snap["takeover_allowed"], last_epoch=snap["last_epoch"],
        )


def _link_snapshot(link: LinkWatch) -> dict[str, Any]:
    d = link.delivery
    return {"last_heard": link.last_heard, "contact_since": link.contact_since,
            "contact_packets": link.contact_packets, "lost": link.lost,
            "quality_heard": link.quality_heard, "low": link.low,
            "last_good": link.last_good,
            "delivery": {"arrivals": [list(a) for a in d.arrivals], "newest": d.newest, "last_t": d.last_t,
                         "repeats": d.repeats}}


def _link_restore(config: WatchConfig, snap: dict[str, Any]) -> LinkWatch:
    d = snap.get("delivery") or {}
    delivery = Delivery(tuple((float(a), int(u)) for a, u in d.get("arrivals", ())), d.get("newest"),
                        d.get("last_t"), d.get("repeats", 0))
    return LinkWatch(config=config, last_heard=snap["last_heard"], contact_since=snap["contact_since"],
                     contact_packets=snap.get("contact_packets", 0), lost=snap["lost"],
                     last_good=snap.get("last_good"), delivery=delivery, quality_heard=snap.get("quality_heard"),
                     low=snap.get("low", False))


def _sub_is_live(sub: tuple[int, ...], newest: tuple[int, ...]) -> bool:
    """A sublease is live if it is the newest one issued or an ancestor of it (older siblings are superseded)."""
    if not newest:
        return sub == (0,)  # operator teleop runs under [E,i,0] before anything was divided
    return newest[: len(sub)] == sub


def _set_claim(claims: tuple[tuple[int, LeaseId], ...], sysid: int, lid: LeaseId) -> tuple[tuple[int, LeaseId], ...]:
    return (*((s, c) for s, c in claims if s != sysid), (sysid, lid))


def _freeze(value: Any) -> Any:
    """JSON lists back to tuples, so restored payloads compare equal to the originals."""
    if isinstance(value, list):
        return tuple(_freeze(v) for v in value)
    if isinstance(value, dict):
        return {k: _freeze(v) for k, v in value.items()}
    return value
