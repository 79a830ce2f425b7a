"""The vehicle: its command authority over the lease book, the parts it is made of, and the real-time shell.

``Vehicle`` is everything onboard except MAVLink framing, and provides the one port every room outside it talks
through (``vehicle.port.VehiclePort``: the command authority, a status snapshot per tick, the event queue);
``vehicle.endpoint.Endpoint`` translates messages into its methods. It is the command authority: every
state-changing request (take or give up the root, claim or expire a lease, arm, hold, teleop, a return plan, a
parameter) is decided by the lease book and its effect kept here, with what the endpoint must announce. It is made of

    control.ControlLoop         the 50 Hz tick: sensors -> estimator -> trail, lease triggers, actuators
    contingency.ReturnDriver    what drives a return-service lease: the plan's service, or an injected behaviour

and what they keep is read where it is kept (``vehicle.control.readings``, ``vehicle.returns.service``, ...) or,
from outside, in the snapshot (``status()``).
Time is always an argument and the robot is reached only through ``RobotDriver``, so the same code runs lockstep
in the simulator, in real time over UDP, or on a real robot. ``run`` is the imperative shell: a clock and a
transport are passed in.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace

from vehicle.contingency import Contingency, ReturnDriver, blocks_for
from vehicle.control import ControlLoop
from vehicle.io import RobotDriver
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
from vehicle.lease_terms import State, refused
from vehicle.linkmap import MapConfig
from vehicle.params import Params
from vehicle.port import DT, NOTHING, Announcements, Status
from vehicle.radio_status import STALE_S as RSSI_STALE_S
from vehicle.service import PlanItem, blocks_from_items, default_plan
from vehicle.teleop import MAX_TELEOP_SPEED, MAX_TELEOP_YAW_RATE, SETPOINT_TTL, Setpoint, velocity_to_command

__all__ = ["DT", "MAX_TELEOP_SPEED", "MAX_TELEOP_YAW_RATE", "SETPOINT_TTL", "Contingency", "Setpoint", "State",
           "Vehicle", "run", "velocity_to_command"]


class Vehicle:
    """The onboard state machine around the pure parts. Mutable: it is the shell that owns the current book.

    It provides ``vehicle.port.VehiclePort``; nothing outside the core changes its fields."""

    def __init__(self, driver: RobotDriver, params: Params, pose: tuple[float, float, float], t: float = 0.0,
                 seed: int = 0, boot_epoch: int | None = None, contingency: Contingency | None = None) -> None:
        """``boot_epoch``: the first epoch to issue, drawn at boot by a real-time vehicle (``vehicle.epochs``);
        None derives it from ``seed``, as only the lockstep simulator may (§3.1). ``contingency``: a link-loss
        behaviour to fly instead of the return plan (the simulator's baselines)."""
        self.driver = driver
        self.params = params
        self.seed = seed
        self.contingency = contingency
        self.on_epoch: Callable[[int], str | None] | None = None  # told of each epoch issued, before its ACK
        self.home = (pose[0], pose[1])
        self.t = t
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
        self.returns = ReturnDriver(self)
        self.control = ControlLoop(self, self.returns, pose, t)
        # the parts' own objects, shared: the estimator, the trail and the plan items reached (MISSION_ITEM_REACHED,
        # drained by the endpoint)
        self.estimator = self.control.estimator
        self.trail = self.control.trail
        self.linkmap = self.control.linkmap
        self._map_owner: int | None = None  # whose packets the link map counts (a new owner has its own rate)
        self.rssi_report: tuple[float, float] | None = None  # (t, dBm): the radio's last report of the owner's signal
        self.station_heard_at: float | None = None  # a trusted frame from a station other than the owner, last heard
        self._ticks = 0  # counts the start and the end of every tick: a snapshot belongs to one stretch between
        self._status: Status | None = None
        self._status_tick = -1

    def tick(self, t: float) -> tuple[float, float]:
        """One 50 Hz tick (``ControlLoop.tick``): the speed and yaw rate commanded. A snapshot taken before it
        belongs to the last tick, one taken during it (an injected contingency's) to this one so far."""
        self._ticks += 1
        out = self.control.tick(t)
        self._ticks += 1
        return out

    # ----- the port: the snapshot and the event queue ------------------------------------------------------
    def status(self) -> Status:
        """The snapshot of now (``vehicle.port.Status``), built at most once per tick: it is kept while the tick,
        the lease book, the arming, the hold, the running block and the estimate are the very objects it was built
        from (identity checks, no comparison of values), and built again when a command between two ticks changed
        one of them, so an answer never shows a lease that is gone."""
        c = self.control
        pose = c.estimator.pose
        s = self._status
        svc = self.returns.service
        if (s is not None and self._status_tick == self._ticks and s.book is self.book and s.pose is pose
                and s.block is svc and s.armed == self.armed and s.holding == self.holding):
            return s
        r = c.readings
        fix = r.fix if r is not None else None
        cont = self.contingency
        running = svc is not None
        s = self._status = Status(
            self.t, pose, r.speed if r is not None else 0.0, r.yaw_rate if r is not None else 0.0, r is not None,
            fix.std if fix is not None else None, c.estimator.fixes_used, c.last_fix, c.last_fix_t, self.armed,
            self.holding, cont is not None and cont.holding, self.state(), self.home, self.driver.mav_type,
            self.book, c.link_is_good, c.outbound_speed, c.command_out, svc,
            self.returns.displacement(pose.x, pose.y) if running else 0.0,
            self.returns.route_remaining() if running else 0.0, c.trail.count)
        self._status_tick = self._ticks
        return s

    def announce(self, text: str) -> None:
        """A notice for the ground stations, queued with the core's own."""
        self.notices.append(text)

    def drain(self) -> Announcements:
        """The transitions and notices queued since the last drain; the queue is left empty."""
        if not self.events and not self.notices:  # (most ticks)
            return NOTHING
        out = Announcements(tuple(self.events), tuple(self.notices))
        self.events.clear()
        self.notices.clear()
        return out

    def drain_reached(self) -> tuple[int, ...]:
        """The plan items reached since the last drain; the list is left empty."""
        reached = self.returns.reached
        if not reached:
            return ()
        out = tuple(reached)
        reached.clear()
        return out

    def trail_points(self):
        """The breadcrumb trail's points (estimate frame), oldest first: an (n, 2) copy."""
        return self.trail.points()

    def linkmap_cells(self) -> list:
        """The owner's link over space, cell by cell, for the file a station fetches."""
        return self.linkmap.cells()

    def param_values(self) -> dict[str, float]:
        """Every parameter's value now, a copy."""
        return dict(self.params.values)

    def refused(self) -> None:
        """A state change refused outside the lease book (the signing gate, a companion's router): counted."""
        self.commands_rejected += 1

    def bind_key(self) -> None:
        """A signing key is installed: the root only by an explicit signed request from now on (§4.1)."""
        self.key_bound = True

    def robot_armed(self, armed: bool) -> None:
        """The robot reports its own arming (a companion's autopilot): the vehicle follows it."""
        self.armed = armed

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

    def verdict(self, sender: int) -> Check:
        """What the lease rules say of a state change from ``sender`` under its last claimed lease now; nothing is
        done or counted."""
        return self.book.check(sender)

    def grants(self, sender: int, compid: int, t: float) -> bool:
        """Whether LEASE_AUTOGRANT would make ``sender`` the owner now; nothing is granted."""
        return sender != self.book.owner and self.book.admit(sender, compid, t, self.seed).book.owner == sender

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

    def heard(self, sysid: int, t: float, seq: int | None = None) -> None:
        """A frame from ``sysid`` with MAVLink sequence number ``seq``: the owner's feed the link watch."""
        self.book = self.book.heard(sysid, t, seq)
        if sysid != self.book.owner:
            self.station_heard_at = t  # (a seeking return ends on it: a station is there, DESIGN §6.2)
        if sysid == self.book.owner:
            if sysid != self._map_owner:
                self._map_owner = sysid
                self.linkmap.forget_sender()
            self.linkmap.packet(t, seq)

    def radio_rssi(self, dbm: float, t: float | None = None) -> None:
        """The vehicle's own radio reports the owner's signal strength at ``t`` (default: this tick), from a SiK
        radio's RADIO_STATUS (``vehicle.radio_status``) or the simulator's channel: the link map keeps its mean per
        place, and the crumbs laid while it is fresh carry it in their link tag (``rssi_at``). It never decides a
        loss or a regain: the owner's packet delivery and silence do (``vehicle.link_watch``)."""
        self.linkmap.rssi(dbm)
        self.rssi_report = (self.t if t is None else t, dbm)

    def rssi_at(self, t: float) -> float:
        """The owner's signal at the robot now (dBm): the radio's last report if at most RSSI_STALE_S old, else
        nan (unknown: no radio, or it stopped reporting)."""
        r = self.rssi_report
        return r[1] if r is not None and t - r[0] <= RSSI_STALE_S else math.nan

    # ----- the root and the execution leases ---------------------------------------------------------------
    def acquire(self, sender: int, compid: int, t: float, allow_takeover: bool) -> Check:
        why = self.book.take_refusal(sender, t)
        if why is not None:
            return self._reject(refused(RejectReason.NOT_IN_CONTROL, why))
        if self.book.owner == sender:
            self.book = replace(self.book, takeover_allowed=allow_takeover)
            return Check(Verdict.EXECUTE, self.book.current_id)
        self.apply(self.book.acquire(sender, compid, t, self.seed, allow_takeover))
        self.setpoint = None
        return Check(Verdict.EXECUTE, self.book.current_id)

    def release(self, sender: int, t: float) -> Check:
        if self.book.owner != sender:
            return self._reject(refused(RejectReason.NOT_IN_CONTROL, "not the owner"))
        self.apply(self.book.release(sender, t))
        self.setpoint = None
        return Check(Verdict.EXECUTE)

    def claim(self, sender: int, epoch: int, index: int, t: float) -> Check:
        return self._answer(*self.book.claim(sender, epoch, index, t))

    def expire(self, sender: int, epoch: int, index: int, t: float) -> Check:
        return self._answer(*self.book.expire(sender, epoch, index, t))

    def rtl(self, sender: int, compid: int, t: float) -> Check:
        """RTL button or RTL mode: OPERATOR_EXPIRE of the operator lease, so the return plan runs."""
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
    def plan_leases(self) -> int:
        """How many execution leases the stored return plan makes."""
        return len(self.book.plan)

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

    def return_now(self, items: tuple[PlanItem, ...], sender: int, compid: int, t: float) -> Check:
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

    def set_param(self, name: str, value: float) -> float:
        """Store a parameter (ParamError leaves the old value) and apply it to the rules at once."""
        v = self.params.set(name, value)
        self.book = self.book.with_config(LeaseConfig.from_params(self.params))
        if name.startswith("LNK_MAP_") or name == "LNK_MIN_Q":
            self.linkmap.with_config(MapConfig.from_params(self.params))
        if not self.plan_items and name.startswith("RTL_"):
            self.apply(self.book.schedule_plan(self._blocks(default_plan(self.params)), self.t))
        return v

    # ----- queries -----------------------------------------------------------------------------------------
    def state(self) -> int:
        """RETURNLINK_STATE now."""
        cur = self.book.current
        if cur is None:
            return State.NO_OWNER
        if cur.holder is Holder.OPERATOR:
            return State.TELEOP if cur.claimed else State.AWAITING_CLAIM
        return self.returns.state()

    def link_good(self, t: float) -> bool:
        """The link tag of a crumb laid now (the link watch decides)."""
        return self.book.owner is not None and self.book.link.good(t)

    def displacement(self) -> float:
        if self.returns.service is None:
            return 0.0
        p = self.estimator.pose
        return self.returns.displacement(p.x, p.y)

    def route_remaining(self) -> float:
        return self.returns.route_remaining()


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
