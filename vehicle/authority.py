"""The command authority of the vehicle: every state-changing request (take or give up the root, claim or expire a
lease, arm, hold, teleop, a return plan) decided by the lease book, its effect kept, and what the ground stations
must hear of it queued (docs/architecture.md §2, the port's face (a)).

``Authority`` is the part of ``vehicle.app.Vehicle`` that holds the lease book and what the operator's executed
commands left (arming, hold, the teleop setpoint, the uploaded plan); the vehicle adds the parts that act on them
(the control loop, the return driver, the link map) and the snapshot. Time is always an argument.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from vehicle.contingency import Contingency, blocks_for
from vehicle.lease import (
    Check,
    ExpireReason,
    Holder,
    LeaseBook,
    LeaseConfig,
    LeaseEvent,
    LeaseId,
    Outcome,
    QueuedCommand,
    RejectReason,
    ServiceBlock,
    Verdict,
    epoch_before,
)
from vehicle.lease_terms import refused
from vehicle.params import Params
from vehicle.service import PlanItem, blocks_from_items, default_plan
from vehicle.teleop import SETPOINT_TTL, Setpoint


class Authority:
    """The lease book and the requests it decides. Mutable: it is the shell that owns the current book; a request
    answers with a verdict (``Check``) or a reason, and every refusal is counted."""

    t: float  # the vehicle's clock: a teleop setpoint lives SETPOINT_TTL from now

    def __init__(self, params: Params, seed: int, contingency: Contingency | None, boot_epoch: int | None,
                 on_epoch: Callable[[int], str | None] | None = None) -> None:
        """``boot_epoch``: the first epoch to issue, drawn at boot by a real-time vehicle (``vehicle.epochs``);
        None derives it from ``seed``, as only the lockstep simulator may (§3.1). ``contingency``: a link-loss
        behaviour to fly instead of the return plan (the simulator's baselines). ``on_epoch``: told of each epoch
        issued, before anyone hears of it (a problem it answers is announced)."""
        self.params = params
        self.seed = seed
        self.contingency = contingency
        self.on_epoch = on_epoch
        self.book = LeaseBook(LeaseConfig.from_params(params), plan=self._blocks(default_plan(params)),
                              last_epoch=None if boot_epoch is None else epoch_before(boot_epoch))
        self.plan_items: tuple[PlanItem, ...] = ()  # the uploaded return plan (empty: the default plan)
        # what the operator's executed commands left: the actuators act on these
        self.armed = False
        self.holding = False  # the operator asked for HOLD (shown as AUTO_LOITER until it drives again)
        self.setpoint: Setpoint | None = None
        self.key_bound = False  # a signing key is installed: the root only by an explicit signed request (§4.1)
        # everything the endpoint must announce, drained by it each tick
        self.events: list[LeaseEvent] = []
        self.event_log: list[LeaseEvent] = []  # every transition since boot, for the record
        self.notices: list[str] = []
        self.commands_rejected = 0  # rejections are never silent: each is answered and counted

    # ----- lease transitions -------------------------------------------------------------------------------
    def apply(self, out: Outcome) -> None:
        """Take the book a transition made, announce its events and execute the commands it released."""
        if out.book is self.book and not out.events and not out.released:
            return  # nothing happened (most ticks): the same book, no event, no command
        issued = out.book.last_epoch != self.book.last_epoch
        self.book = out.book
        if issued and self.on_epoch is not None and out.book.last_epoch is not None:
            problem = self.on_epoch(out.book.last_epoch)  # kept before anyone hears of the new epoch
            if problem:
                self.notices.append(problem)
        self.events.extend(out.events)
        self.event_log.extend(out.events)
        for ev in out.events:
            self.notices.append(ev.describe())
        for q in out.released:
            self._execute(q.payload, q.lease, q.sender)

    def _blocks(self, blocks: tuple[ServiceBlock, ...]) -> tuple[ServiceBlock, ...]:
        return blocks_for(self.contingency, blocks)

    def refuses(self, sender: int) -> bool:
        """Someone else owns the vehicle: a state change from ``sender`` is refused, and counted."""
        if self.book.owner is not None and self.book.owner != sender:
            self.commands_rejected += 1
            return True
        return False

    def verdict(self, sender: int, compid: int | None = None, t: float | None = None) -> Check:
        """What the lease rules say of a state change from ``sender`` under its last claimed lease now; nothing is
        done or counted. Given ``compid`` and ``t``, as after LEASE_AUTOGRANT: a plain client it would make the
        owner now is answered under the lease it would get (the book's ``admit`` is a value: nothing is granted)."""
        book = self.book
        if compid is not None and t is not None and not self.key_bound:
            book = book.admit(sender, compid, t, self.seed).book
        return book.check(sender)

    def _reject(self, chk: Check) -> Check:
        self.commands_rejected += 1
        return chk

    def _answer(self, out: Outcome, chk: Check) -> Check:
        self.apply(out)
        return chk if chk.executes else self._reject(chk)

    def admit(self, sender: int, compid: int, t: float) -> None:
        """A plain client's state-changing command may grant it the root (LEASE_AUTOGRANT)."""
        if self.key_bound:
            return  # with a signing key, LEASE_AUTOGRANT does nothing: the owner is bound to the key
        self.apply(self.book.admit(sender, compid, t, self.seed))

    # ----- the root and the execution leases ---------------------------------------------------------------
    def operator_control(self, sender: int, compid: int, t: float, request: bool, allow_takeover: bool) -> Check:
        """MAV_CMD_REQUEST_OPERATOR_CONTROL: take the root (``request``; ``allow_takeover`` says whether another
        station may take it over from then on) or give it up."""
        if request:
            return self._acquire(sender, compid, t, allow_takeover)
        return self._release(sender, t)

    def _acquire(self, sender: int, compid: int, t: float, allow_takeover: bool) -> Check:
        why = self.book.take_refusal(sender, t)
        if why is not None:
            return self._reject(refused(RejectReason.NOT_IN_CONTROL, why))
        if self.book.owner == sender:
            self.book = replace(self.book, takeover_allowed=allow_takeover)
            return Check(Verdict.EXECUTE, self.book.current_id)
        self.apply(self.book.acquire(sender, compid, t, self.seed, allow_takeover))
        self.setpoint = None
        return Check(Verdict.EXECUTE, self.book.current_id)

    def _release(self, sender: int, t: float) -> Check:
        if self.book.owner != sender:
            return self._reject(refused(RejectReason.NOT_IN_CONTROL, "not the owner"))
        self.apply(self.book.release(sender, t))
        self.setpoint = None
        return Check(Verdict.EXECUTE)

    def claim(self, sender: int, epoch: int, index: int, t: float) -> Check:
        return self._answer(*self.book.claim(sender, epoch, index, t))

    def expire(self, sender: int, epoch: int, index: int, t: float) -> Check:
        return self._answer(*self.book.expire(sender, epoch, index, t))

    def rtl(self, sender: int, compid: int, t: float, items: tuple[PlanItem, ...] = ()) -> Check:
        """RTL button or RTL mode: OPERATOR_EXPIRE of the operator lease, so the return plan runs; with ``items``
        (MAV_CMD_NAV_RETURN_TO_LINK as a command), those run now as one return block (``_return_now``)."""
        if items:
            return self._return_now(items, sender, compid, t)
        self.admit(sender, compid, t)
        return self._answer(*self.book.expire_current(sender, t))

    def take_manual(self, sender: int, compid: int, t: float) -> Check:
        """A plain client switching to a manual mode (or HOLD) takes the operator lease back: it claims the
        unclaimed operator lease, or a newer lease over a running return (NEWER_LEASE). Only the owner can."""
        self.admit(sender, compid, t)
        book = self.book
        if book.owner is None or book.owner != sender or book.epoch is None:
            return self._reject(refused(RejectReason.NOT_IN_CONTROL, "not the owner"))
        cur = book.current
        assert cur is not None
        if cur.holder is Holder.OPERATOR and not cur.claimed:
            return self.claim(sender, book.epoch, -1, t)  # resume: the fresh operator lease
        if cur.holder is Holder.OPERATOR and book.claimed_by(sender) == book.current_id:
            return book.check(sender)  # already driving under the current lease
        return self.claim(sender, book.epoch, book.next_index, t)  # over a return: a newer lease

    # ----- commands under a lease --------------------------------------------------------------------------
    def command(self, sender: int, compid: int, t: float, payload: tuple) -> Check:
        """A standard state-changing command under the sender's last claimed lease (§3.4)."""
        self.admit(sender, compid, t)
        chk = self.book.check(sender)
        if chk.verdict is Verdict.QUEUE and chk.lease is not None:
            self.book = self.book.enqueue(QueuedCommand(chk.lease, sender, payload))
            return chk
        if not chk.executes:
            return self._reject(chk)
        self._execute(payload, chk.lease, sender)
        return chk

    def drop_setpoint(self) -> None:
        """The tick found the setpoint spent (stale, its lease gone, a return drives): none drives until the operator
        sends one."""
        self.setpoint = None

    def _execute(self, payload: tuple, lease: LeaseId | None, sender: int) -> None:
        """What an executed command does: ``("teleop", speed, yaw_rate)``, ``("hold",)`` or ``("arm", on)``."""
        kind = payload[0]
        if kind == "teleop" and lease is not None:
            _, speed, yaw_rate = payload
            self.setpoint = Setpoint(speed, yaw_rate, lease, self.t + SETPOINT_TTL, sender)
            if speed or yaw_rate:
                self.holding = False
        elif kind == "hold":
            self.setpoint = None
            self.holding = True
        elif kind == "arm":
            self.armed = bool(payload[1])
            if not self.armed:
                self.setpoint = None

    # ----- the return plan and the parameters --------------------------------------------------------------
    def set_plan(self, items: tuple[PlanItem, ...], t: float) -> str | None:
        """A mission upload is the return plan: scheduled as leases behind the operator lease. Returns why not."""
        try:
            blocks = blocks_from_items(items, self.params) if items else default_plan(self.params)
        except ValueError as e:
            return str(e)
        if not blocks:
            blocks = default_plan(self.params)
        self.plan_items = tuple(items)
        self.apply(self.book.schedule_plan(self._blocks(blocks), t))
        return None

    def _return_now(self, items: tuple[PlanItem, ...], sender: int, compid: int, t: float) -> Check:
        """MAV_CMD_NAV_RETURN_TO_LINK as a command: run these items as one return block now; the stored plan
        stays the one re-armed afterwards."""
        self.admit(sender, compid, t)
        cur = self.book.current
        if self.book.owner != sender or cur is None:
            return self._reject(refused(RejectReason.NOT_IN_CONTROL, "not the owner"))
        if cur.holder is not Holder.OPERATOR:
            return Check(Verdict.EXECUTE, self.book.current_id, detail="a return is already running")
        self.apply(self.book.schedule_plan(self._blocks(blocks_from_items(items, self.params)), t, store=False))
        return self.rtl(sender, compid, t)

    def preempt(self, t: float, reason: ExpireReason, why: str) -> bool:
        """The robot left the vehicle's hands from outside the lease book (companion mode: an autopilot's pilot or
        failsafe changed its mode, or the autopilot stopped answering): the current lease and its chain end with
        ``reason``, said in words by ``why``, and a fresh operator lease waits for a claim. A return never fights
        whoever took the robot. True if a lease ended (and ``why`` was announced)."""
        out = self.book.interrupt(t, reason)
        if not out.events:
            return False
        self.notices.append(why)
        self.setpoint = None
        self.apply(out)
        return True

    def set_plan_start(self, seq: int, sender: int, compid: int, t: float) -> str | None:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: the return plan is scheduled from the block holding
        item ``seq`` on. Only while an operator lease is current, and only by the owner."""
        if self.refuses(sender):
            return f"GCS {self.book.owner} is in control"
        items = self.plan_items
        if not 0 <= seq < max(1, len(items)):
            return f"item {seq} does not exist"
        cur = self.book.current
        if cur is not None and cur.holder is not Holder.OPERATOR:
            return "a return is running"
        if not items:
            return None
        blocks = blocks_from_items(items[seq:], self.params)
        # keep the seq numbers of the whole mission
        blocks = tuple(replace(b, payload=tuple(replace(it, seq=it.seq + seq) for it in b.payload)) for b in blocks)
        self.apply(self.book.schedule_plan(self._blocks(blocks), t, store=False))
        return None
