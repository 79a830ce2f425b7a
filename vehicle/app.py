"""The vehicle loop: one 50 Hz tick wires the lease book, estimator, trail, auto-return service and actuators.

``Vehicle`` is everything onboard except MAVLink framing; ``vehicle.mavlink.Endpoint`` translates messages into
its methods. Time is always an argument and the robot is reached only through ``RobotDriver``, so the same code
runs lockstep in the simulator, in real time over UDP, or on a real robot. ``run`` is the imperative shell: a clock
and a transport are passed in.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

from vehicle.estimator import Estimator
from vehicle.io import Readings, RobotDriver
from vehicle.lease import (
    Check,
    ExecutionLease,
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
from vehicle.navigation import TURN_IN_PLACE
from vehicle.params import Params
from vehicle.service import (
    NAV_LOITER_TIME,
    NAV_WAYPOINT,
    PlanItem,
    ServiceState,
    blocks_from_items,
    default_plan,
)
from vehicle.service import displacement as block_displacement
from vehicle.service import start as start_block
from vehicle.service import step as step_block
from vehicle.trail import Crumb, Trail, TrailConfig

# enum members read through their class cost more than a function call (a descriptor lookup each time): what
# runs every tick compares against these module-level names instead
_OPERATOR, _RETURN_SERVICE = Holder.OPERATOR, Holder.RETURN_SERVICE
_EXECUTE = Verdict.EXECUTE

DT = 0.02  # the control tick: 50 Hz
SETPOINT_TTL = 0.5  # s: a teleop setpoint not refreshed this long is dropped (dead-man)
MAX_TELEOP_SPEED = 2.0  # m/s at full stick
MAX_TELEOP_YAW_RATE = 1.2  # rad/s at full stick


class State:
    """RETURNLINK_STATE."""

    NO_OWNER, TELEOP, AWAITING_CLAIM, RETURNING, HOLDING, NAVIGATING = range(6)


# what ``Vehicle.state`` answers every tick, as module-level names (cheaper to read than through the class)
_NO_OWNER, _TELEOP, _AWAITING_CLAIM = State.NO_OWNER, State.TELEOP, State.AWAITING_CLAIM
_RETURNING, _HOLDING, _NAVIGATING = State.RETURNING, State.HOLDING, State.NAVIGATING


@dataclass(frozen=True)
class Setpoint:
    """A teleop request, bound to the lease it was sent under: it dies with that lease."""

    speed: float
    yaw_rate: float
    lease: LeaseId
    until: float
    sender: int = 0


def lease_config(params: Params) -> LeaseConfig:
    return LeaseConfig(link_timeout=params["LNK_TIMEOUT"], regain_s=params["LNK_REGAIN_S"],
                       contact_gap=params["LNK_GOOD_S"], min_quality=params["LNK_MIN_Q"],
                       rearm=bool(params["RTL_REARM"]),
                       autogrant=bool(params["LEASE_AUTOGRANT"]), stale_take=bool(params["LEASE_STALE_TAKE"]))


def trail_config(params: Params) -> TrailConfig:
    return TrailConfig(spacing=params["TRL_SPACING"], tolerance=params["TRL_TOL"],
                       loop_distance=params["TRL_LOOP_D"], max_points=int(params["TRL_MAX_PTS"]))


class Contingency(Protocol):
    """What the vehicle does, in place of its return plan's blocks, while a return-service lease is current.

    The one door for comparing link-loss behaviours on this very vehicle (DESIGN §9): the lease book, its
    triggers, telemetry and MAVLink stay exactly as they are, only the driving during a return differs. The
    simulator's baselines (hold, straight-line RTL, SmartRTL, back-up) implement it; a robot leaves it None.
    """

    halts_on_regain: bool  # False: LINK_REGAINED does not end the running block (it runs to its own end)
    holding: bool  # True while its rules keep the robot standing still (reported as HOLDING, not RETURNING)

    def observe(self, vehicle: Vehicle, t: float) -> None:
        """Every tick, after the estimator: a behaviour that keeps its own memory (SmartRTL's path) records."""

    def drive(self, vehicle: Vehicle, t: float, x: float, y: float, yaw: float) -> tuple[float, float,
                                                                                       ExpireReason | None]:
        """One tick of the current service lease: speed, yaw rate, and why the block ended (None: running)."""


class Vehicle:
    """The onboard state machine around the pure parts. Mutable: it is the shell that owns the current book."""

    def __init__(self, driver: RobotDriver, params: Params, pose: tuple[float, float, float], t: float = 0.0,
                 seed: int = 0, boot_epoch: int | None = None, contingency: Contingency | None = None) -> None:
        """``boot_epoch``: the first epoch to issue, drawn at boot by a real-time vehicle (``vehicle.epochs``);
        None derives it from ``seed``, as only the lockstep simulator may (DESIGN §3.1). ``contingency``: a
        link-loss behaviour to fly instead of the return plan (the simulator's baselines)."""
        self.driver = driver
        self.params = params
        self.seed = seed
        self.contingency = contingency
        self.on_epoch: Callable[[int], str | None] | None = None  # told of each epoch issued, before its ACK
        x, y, yaw = pose
        self.home = (x, y)
        self.estimator = Estimator(x, y, yaw, t, pos_std=0.3, yaw_std=0.02)
        self.trail = Trail(trail_config(params))
        self.book = LeaseBook(lease_config(params), plan=self._blocks(default_plan(params)),
                              last_epoch=None if boot_epoch is None else epoch_before(boot_epoch))
        self.plan_items: tuple[PlanItem, ...] = ()  # the uploaded return plan (empty: the default plan)
        self.t = t
        self.armed = False
        self.holding = False  # the operator asked for HOLD (shown as AUTO_LOITER until it drives again)
        self.setpoint: Setpoint | None = None
        self.service: ServiceState | None = None
        self.service_index: int | None = None
        self.outbound_speed = 0.0
        self.readings: Readings | None = None
        self._crumbs: deque[Crumb] = deque()  # recorded, waiting for their link tag to be final
        self.last_fix: tuple[float, float] | None = None  # the last fix used, for GPS_RAW_INT
        self.last_fix_t: float | None = None
        self.command_out = (0.0, 0.0)
        self.link_is_good = False  # this tick's link tag (owner heard recently, with good quality)
        self.key_bound = False  # a signing key is installed: the root only by an explicit signed request (§4.1)
        # everything the endpoint must announce, drained by it each tick
        self.events: list[LeaseEvent] = []
        self.event_log: list[LeaseEvent] = []  # every transition since boot, for the record
        self.notices: list[str] = []
        self.reached: list[int] = []  # plan items reached (MISSION_ITEM_REACHED)
        # counters for the record: rejections are never silent, stale executions must stay 0
        self.commands_rejected = 0
        self.stale_commands_executed = 0
        self.service_faults = 0  # return blocks ended because the service raised (each reported, never fatal)
        # the (book, setpoint) pair the teleop guards last passed (see ``_teleop``)
        self._cleared: tuple[LeaseBook | None, Setpoint | None] = (None, None)

    # ----- lease transitions -------------------------------------------------------------------------------
    def _apply(self, out: Outcome) -> None:
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
        """The blocks as the lease book schedules them: a contingency that does not halt when the link comes
        back (SmartRTL) keeps its block running through LINK_REGAINED."""
        c = self.contingency
        if c is None or c.halts_on_regain:
            return blocks
        return tuple(replace(b, halt_on_regain=False) for b in blocks)

    def refuses(self, sender: int) -> bool:
        """Someone else owns the vehicle: a state change from ``sender`` is refused, and counted."""
        if self.book.owner is not None and self.book.owner != sender:
            self.commands_rejected += 1
            return True
        return False

    def _reject(self, chk: Check) -> Check:
        self.commands_rejected += 1
        return chk

    def admit(self, sender: int, compid: int, t: float) -> None:
        """A plain client's state-changing command may grant it the root (LEASE_AUTOGRANT)."""
        if self.key_bound:
            return  # with a signing key, LEASE_AUTOGRANT does nothing: the owner is bound to the key
        self._apply(self.book.admit(sender, compid, t, self.seed))

    def heard(self, sysid: int, t: float, seq: int | None = None) -> None:
        """A frame from ``sysid`` with MAVLink sequence number ``seq``: the owner's feed the link watch."""
        self.book = self.book.heard(sysid, t, seq)

    def acquire(self, sender: int, compid: int, t: float, allow_takeover: bool) -> Check:
        why = self.book.take_refusal(sender, t)
        if why is not None:
            return self._reject(Check(Verdict.REJECT, None, RejectReason.NOT_IN_CONTROL, why))
        if self.book.owner == sender:
            self.book = replace(self.book, takeover_allowed=allow_takeover)
            return Check(Verdict.EXECUTE, self.book.current_id)
        self._apply(self.book.acquire(sender, compid, t, self.seed, allow_takeover))
        self.setpoint = None
        return Check(Verdict.EXECUTE, self.book.current_id)

    def release(self, sender: int, t: float) -> Check:
        if self.book.owner != sender:
            return self._reject(Check(Verdict.REJECT, None, RejectReason.NOT_IN_CONTROL, "not the owner"))
        self._apply(self.book.release(sender, t))
        self.setpoint = None
        return Check(Verdict.EXECUTE)

    def claim(self, sender: int, epoch: int, index: int, t: float) -> Check:
        out, chk = self.book.claim(sender, epoch, index, t)
        self._apply(out)
        return chk if chk.executes else self._reject(chk)

    def expire(self, sender: int, epoch: int, index: int, t: float) -> Check:
        out, chk = self.book.expire(sender, epoch, index, t)
        self._apply(out)
        return chk if chk.executes else self._reject(chk)

    def rtl(self, sender: int, compid: int, t: float) -> Check:
        """RTL button or RTL mode: OPERATOR_EXPIRE of the operator lease, so the return plan runs."""
        self.admit(sender, compid, t)
        out, chk = self.book.expire_current(sender, t)
        self._apply(out)
        return chk if chk.executes else self._reject(chk)

    def take_manual(self, sender: int, compid: int, t: float) -> Check:
        """A plain client switching to a manual mode (or HOLD) takes the operator lease back: it claims the
        unclaimed operator lease, or a newer lease over a running return (NEWER_LEASE). Only the owner can."""
        self.admit(sender, compid, t)
        book = self.book
        if book.owner is None or book.owner != sender or book.epoch is None:
            return self._reject(Check(Verdict.REJECT, None, RejectReason.NOT_IN_CONTROL, "not the owner"))
        cur = book.current
        assert cur is not None
        if cur.holder is Holder.OPERATOR and not cur.claimed:
            return self.claim(sender, book.epoch, -1, t)  # resume: the fresh operator lease
        if cur.holder is Holder.OPERATOR and book.claimed_by(sender) == book.current_id:
            return book.check(sender)  # already driving under the current lease
        return self.claim(sender, book.epoch, book.next_index, t)  # over a return: a newer lease

    def command(self, sender: int, compid: int, t: float, payload: tuple) -> Check:
        """A standard state-changing command under the sender's last claimed lease (DESIGN §3.4)."""
        self.admit(sender, compid, t)
        chk = self.book.check(sender)
        if chk.verdict is Verdict.QUEUE and chk.lease is not None:
            self.book = self.book.enqueue(QueuedCommand(chk.lease, sender, payload))
            return chk
        if not chk.executes:
            return self._reject(chk)
        self._execute(payload, chk.lease, sender)
        return chk

    def _execute(self, payload: tuple, lease: LeaseId | None, sender: int) -> None:
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

    def set_plan(self, items: tuple[PlanItem, ...], t: float) -> str | None:
        """A mission upload is the return plan: scheduled as leases behind the operator lease. Returns why not."""
        try:
            blocks = blocks_from_items(items, self.params) if items else default_plan(self.params)
        except ValueError as e:
            return str(e)
        if not blocks:
            blocks = default_plan(self.params)
        self.plan_items = tuple(items)
        self._apply(self.book.schedule_plan(self._blocks(blocks), t))
        return None

    def return_now(self, items: tuple[PlanItem, ...], sender: int, compid: int, t: float) -> Check:
        """MAV_CMD_NAV_RETURN_TO_LINK as a command: run these items as one return block now; the stored plan
        stays the one re-armed afterwards."""
        self.admit(sender, compid, t)
        cur = self.book.current
        if self.book.owner != sender or cur is None:
            return self._reject(Check(Verdict.REJECT, None, RejectReason.NOT_IN_CONTROL, "not the owner"))
        if cur.holder is not Holder.OPERATOR:
            return Check(Verdict.EXECUTE, self.book.current_id, detail="a return is already running")
        self._apply(self.book.schedule_plan(self._blocks(blocks_from_items(items, self.params)), t, store=False))
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
        self._apply(out)
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
        self._apply(self.book.schedule_plan(self._blocks(blocks), t, store=False))
        return None

    def route_remaining(self) -> float:
        st = self.service
        if st is None or st.path is None:
            return 0.0
        return max(0.0, st.path.length - st.progress)

    def set_param(self, name: str, value: float) -> float:
        """Store a parameter (ParamError leaves the old value) and apply it to the rules at once."""
        v = self.params.set(name, value)
        self.book = self.book.with_config(lease_config(self.params))
        if not self.plan_items and name.startswith("RTL_"):
            self._apply(self.book.schedule_plan(self._blocks(default_plan(self.params)), self.t))
        return v

    # ----- queries -----------------------------------------------------------------------------------------
    def state(self) -> int:
        """RETURNLINK_STATE now. Asked several times a tick (telemetry, the simulator's record): the states are
        module-level names (a class attribute read costs more)."""
        cur = self.book.current
        if cur is None:
            return _NO_OWNER
        if cur.holder is _OPERATOR:
            return _TELEOP if cur.claimed else _AWAITING_CLAIM
        if self.contingency is not None:
            return _HOLDING if self.contingency.holding else _RETURNING
        st = self.service
        if st is None or st.item < 0:
            return _RETURNING
        command = st.items[st.item].command
        if command == NAV_LOITER_TIME:
            return _HOLDING
        return _NAVIGATING if command == NAV_WAYPOINT else _RETURNING

    def link_good(self, t: float) -> bool:
        """The link tag of a crumb laid now (the link watch decides)."""
        return self.book.owner is not None and self.book.link.good(t)

    def displacement(self) -> float:
        if self.service is None:
            return 0.0
        p = self.estimator.pose
        return block_displacement(self.service, p.x, p.y)

    # ----- the tick ----------------------------------------------------------------------------------------
    def tick(self, t: float) -> tuple[float, float]:
        """Sensors -> estimator -> trail; lease triggers; the current lease's commands -> actuators.

        Run 50 times a second, so it reads each attribute once into a local and takes the pose once: in the
        lockstep simulator this method and what it calls are a third of the vehicle's cost."""
        dt = t - self.t
        self.t = t
        r = self.driver.read(t, dt if dt > 1e-6 else 1e-6)
        self.readings = r
        est = self.estimator
        est.predict(r.speed, r.yaw_rate, t, r.accel)
        if r.heading is not None:
            est.heading(r.heading, r.heading_std)
        fix = r.fix
        if fix is not None and est.fix(fix.x, fix.y, fix.std):
            self.last_fix, self.last_fix_t = (fix.x, fix.y), t
        p = est.pose
        book = self.book
        good = self.link_is_good = self.link_good(t)
        if self.contingency is not None:
            self.contingency.observe(self, t)
        # (``_make`` from every field in order, rssi unknown: it skips the keyword handling of the named tuple's
        # generated ``__new__``, a crumb being recorded every tick)
        self._crumbs.append(Crumb._make((p.x, p.y, t, p.std, good, math.nan)))

        out = book.tick_changes(t)  # (None on most ticks: nothing happened)
        if out is not None:
            self._apply(out)
        book = self.book
        cur = book.current
        # a block about to start plans from the whole trail; afterwards crumbs wait for their true tag again
        starting = cur is not None and cur.holder is _RETURN_SERVICE and self.service_index != cur.index
        self._lay_crumbs(t, flush=starting)
        speed, yaw_rate = self._control(t, cur, p.x, p.y, p.yaw)
        if not self.armed:
            speed, yaw_rate = 0.0, 0.0
        self.command_out = (speed, yaw_rate)
        self.driver.command(speed, yaw_rate)
        return speed, yaw_rate

    def _lay_crumbs(self, t: float, flush: bool) -> None:
        """Crumbs reach the trail once their link tag is final, LNK_GOOD_S after they were recorded.

        A crumb is link-good only if the owner was heard well there *and* heard well again afterwards: the last
        stretch before the link died was driven while the silence was still shorter than LNK_GOOD_S, and must
        not become a return target. A block about to start needs the whole trail, so it flushes them with what is
        known; crumbs laid while it runs wait for their true tag like any other (a return over a good link lays
        good crumbs, and a later return must not take them for lost ones and drive away from the operator).
        """
        crumbs = self._crumbs
        horizon = t if flush else t - self.params["LNK_GOOD_S"]
        last = self.book.link.last_good
        add = self.trail.add
        while crumbs and crumbs[0].t <= horizon:
            c = crumbs.popleft()
            good = c.link_good and last is not None and last >= c.t
            add(c if good == c.link_good else c._replace(link_good=good))

    def _control(self, t: float, cur: ExecutionLease | None, x: float, y: float, yaw: float) -> tuple[float, float]:
        """The commands of ``cur``, the book's current lease (the tick has it in hand already)."""
        book = self.book
        if cur is None or cur.holder is _OPERATOR:
            self.service, self.service_index = None, None
            return self._teleop(t)
        self.setpoint = None
        if self.contingency is not None:
            return self._contingency(t, x, y, yaw)
        link_lost = book.link.lost
        fresh = self.service is None or self.service_index != cur.index
        try:
            if fresh:
                step = start_block(cur.block, x, y, t, self.trail, self.params, link_lost, self.outbound_speed)
            else:
                step = step_block(self.service, x, y, yaw, t, self.trail, self.params, link_lost,
                                  self.outbound_speed, slipping=self.estimator.slipping)
        except Exception as e:  # noqa: BLE001 - the return runs when nobody can restart the vehicle
            return self._service_fault(cur.index, e, t)
        if fresh:
            self.service_index = cur.index
        if step.replanned and book.current_id is not None:
            if not fresh and self.service is not None:
                self.reached.append(self.service.items[self.service.item].seq)
            self.book, _ = self.book.issue_sublease(book.current_id)
        self.service = step.state
        if step.finished is not None:
            st = step.state
            if step.finished is ExpireReason.COMPLETED and 0 <= st.item < len(st.items):
                self.reached.append(st.items[st.item].seq)
            self._apply(self.book.finish(cur.index, step.finished, t))
            return 0.0, 0.0
        return step.speed, step.yaw_rate

    def _service_fault(self, index: int, error: Exception, t: float) -> tuple[float, float]:
        """The return service raised: end its block as STUCK (the next block of the chain, or a fresh operator
        lease, takes over), hold still this tick, and say so. A fault here must never end the process: the
        return runs exactly when the link is gone and nobody could restart it."""
        self.service_faults += 1
        self.service, self.service_index = None, None
        self.notices.append(f"return service fault in lease {index}: {type(error).__name__}: {error}; "
                            f"block ended, holding")
        self._apply(self.book.finish(index, ExpireReason.STUCK, t))
        return 0.0, 0.0

    def _contingency(self, t: float, x: float, y: float, yaw: float) -> tuple[float, float]:
        """The injected behaviour drives the current service lease, under a sublease of it like any return."""
        cur = self.book.current
        assert cur is not None and self.contingency is not None
        if self.service_index != cur.index and self.book.current_id is not None:
            self.service, self.service_index = None, cur.index
            self.book, _ = self.book.issue_sublease(self.book.current_id)
        speed, yaw_rate, finished = self.contingency.drive(self, t, x, y, yaw)
        if finished is not None:
            self._apply(self.book.finish(cur.index, finished, t))
            return 0.0, 0.0
        return speed, yaw_rate

    def _teleop(self, t: float) -> tuple[float, float]:
        sp = self.setpoint
        if sp is None:
            return 0.0, 0.0
        if t > sp.until:
            self.setpoint = None
            return 0.0, 0.0
        book = self.book
        if self._cleared[0] is not book or self._cleared[1] is not sp:
            # (skipped when both guards passed for this very book and setpoint: both are immutable and the guards
            # pure reads of them, so on most ticks of a drive the verdict is already known)
            if book.check(book.owner or 0, sp.lease).verdict is not _EXECUTE:
                # the lease this setpoint was sent under is gone: it must not drive the robot any more
                self.setpoint = None
                return 0.0, 0.0
            # (``book.current_id`` compared by its parts: it builds a frozen LeaseId each time it is read)
            cur = book.current
            if cur is None or book.epoch is None or sp.lease.path[0] != cur.index:
                # a last guard at the actuator, independent of how the setpoint got here: never drive on it
                self.stale_commands_executed += 1
                self.setpoint = None
                return 0.0, 0.0
            self._cleared = (book, sp)
        if abs(sp.speed) > 0.2 and self.readings is not None:
            self.outbound_speed += 0.02 * (abs(self.readings.speed) - self.outbound_speed)
        return sp.speed, sp.yaw_rate


def velocity_to_command(vn: float, ve: float, yaw_rate: float | None, yaw: float) -> tuple[float, float]:
    """A NED velocity target for a unicycle: turn toward the velocity, drive the part of it along the heading.

    Far off the heading it turns in place first, as the return's navigator does: driving the cosine share of a
    velocity 60 degrees off swings a wide arc, and a robot left facing away from its way out (a return backs up)
    would sweep a U-turn into the corridor wall."""
    speed = math.hypot(vn, ve)
    if speed < 1e-3:
        return 0.0, yaw_rate or 0.0
    err = (math.atan2(ve, vn) - yaw + math.pi) % (2 * math.pi) - math.pi
    turn = max(-MAX_TELEOP_YAW_RATE, min(MAX_TELEOP_YAW_RATE, 2.0 * err)) if yaw_rate is None else yaw_rate
    if abs(err) > TURN_IN_PLACE:
        return 0.0, turn
    return speed * math.cos(err), turn


def run(vehicle: Vehicle, endpoint, receive: Callable[[float], list], send: Callable[[bytes, float], None],
        clock: Callable[[], float] = time.monotonic, stop: Callable[[], bool] = lambda: False,
        sleep: Callable[[float], None] = time.sleep, speedup: float = 1.0,
        after_tick: Callable[[float], None] | None = None,
        wait: Callable[[float], bool] | None = None) -> None:
    """The real-time shell around one vehicle: 50 Hz ticks paced by ``clock`` (``speedup`` times faster),
    frames in through ``receive(t)`` (bytes, or (bytes, source address)) and out through ``send(frame, t)``,
    until ``stop()``.

    ``wait(timeout) -> bool`` (True: input is ready before the timeout) lets the link be served between ticks, as
    autopilots service their links faster than their control loop: a command that arrives just after a tick is
    handled at once, at that tick's time, and its COMMAND_ACK leaves then instead of up to a tick later. Between
    ticks only frames are handled and answered; the vehicle, the physics (``after_tick``) and telemetry move on
    the tick. Without ``wait`` the loop sleeps until the next tick.

    A real robot passes a UDP or serial link and its driver; the simulator passes the radio proxy and steps the
    physics in ``after_tick``.
    """
    t0, start = clock(), vehicle.t
    while not stop():
        t = round(vehicle.t + DT, 9)
        _take(endpoint, receive(t), t)
        vehicle.tick(t)
        if after_tick is not None:
            after_tick(t)
        for frame in endpoint.tick(t):
            send(frame, t)
        due = t0 + (t - start) / speedup
        remaining = due - clock()
        while remaining > 0:
            if wait is None:
                sleep(remaining)
                break
            if not wait(remaining):  # nothing came: the next tick is due (or the link failed: sleep instead)
                remaining = due - clock()
                if remaining > 0:
                    sleep(remaining)
                break
            _take(endpoint, receive(t), t)  # input before the next tick: handled and answered now, at this tick's time
            for frame in endpoint.replies():
                send(frame, t)
            remaining = due - clock()


def _take(endpoint, items: list, t: float) -> None:
    """Hand what ``receive`` gave to the endpoint, at time ``t``."""
    for item in items:
        if isinstance(item, tuple):  # (bytes, where they came from): the endpoint learns its owner's address
            endpoint.receive(item[0], t, item[1])
        else:
            endpoint.receive(item, t)
