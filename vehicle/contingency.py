"""What drives the robot while a return-service lease is current (docs/architecture.md §3.5, §6, §9).

The lease book decides *that* a block of the return plan holds the current lease; ``ReturnDriver`` drives it.
Normally that is the auto-return service (``vehicle/service.py``), started when a block becomes current and
stepped every tick under a sublease of its lease that is renewed at every replan. The simulator can inject a
``Contingency`` instead (its baselines: hold, straight-line RTL, SmartRTL, back-up), so the same vehicle, lease
book, triggers and MAVLink fly another link-loss behaviour and only the driving differs.

A fault in the service never ends the process: the return runs exactly when the link is gone and nobody could
restart the vehicle, so a raising block ends as STUCK (the next block of the chain, or a fresh operator lease,
takes over) and the vehicle says so.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Protocol

from vehicle.lease import ExecutionLease, ExpireReason, LeaseBook, Outcome, ServiceBlock
from vehicle.lease_terms import State
from vehicle.link_watch import REGAIN_PACKETS
from vehicle.navigation import FollowerConfig
from vehicle.port import Snapshot, VehiclePort
from vehicle.returning import Way
from vehicle.service import NAV_LOITER_TIME, NAV_WAYPOINT, ServiceState, ServiceStep
from vehicle.service import displacement as block_displacement
from vehicle.service import start as start_block
from vehicle.service import step as step_block
from vehicle.standoff import Sweep, keep_off

if TYPE_CHECKING:
    from vehicle.clearance import FreeSpace
    from vehicle.estimator import Estimator
    from vehicle.linkmap import LinkMap
    from vehicle.params import Params
    from vehicle.trail import Trail


class Onboard(VehiclePort, Protocol):
    """The vehicle as a return is driven on it, from inside the core: what ``ReturnDriver`` reads and changes of
    it. ``vehicle.app.Vehicle`` is the vehicle; it is named here as a protocol, below it, so that the parts it is
    made of (this module and ``vehicle.control``) do not import it back (docs/architecture.md §2). An injected
    ``Contingency`` is outside the core and sees only the port's snapshot face (``Snapshot``)."""

    params: Params
    book: LeaseBook  # the current book: a transition replaces it, through ``apply``
    contingency: Contingency | None  # None: the return plan's blocks drive
    linkmap: LinkMap
    armed: bool
    home: tuple[float, float]
    station_heard_at: float | None  # a station other than the owner, last heard (trusted frames only)
    estimator: Estimator
    trail: Trail

    @property
    def outbound_speed(self) -> float: ...

    @property
    def link_is_good(self) -> bool: ...

    def apply(self, out: Outcome) -> None:
        """Take the book a transition made, announce its events and execute the commands it released."""


class Contingency(Protocol):
    """What the vehicle does, in place of its return plan's blocks, while a return-service lease is current.

    The one door for comparing link-loss behaviours on this very vehicle (§9): the lease book, its triggers,
    telemetry and MAVLink stay exactly as they are, only the driving during a return differs. The simulator's
    baselines (hold, straight-line RTL, SmartRTL, back-up) implement it; a robot leaves it None. It is handed the
    port's snapshot face (``vehicle.port.Snapshot``), as every room outside the core is handed the face it uses: it
    reads and changes nothing.
    """

    halts_on_regain: bool  # False: LINK_REGAINED does not end the running block (it runs to its own end)
    holding: bool  # True while its rules keep the robot standing still (reported as HOLDING, not RETURNING)

    def observe(self, vehicle: Snapshot, t: float) -> None:
        """Every tick, after the estimator: a behaviour that keeps its own memory (SmartRTL's path) records."""

    def drive(self, vehicle: Snapshot, t: float, x: float, y: float, yaw: float) -> tuple[float, float,
                                                                                           ExpireReason | None]:
        """One tick of the current service lease: speed, yaw rate, and why the block ended (None: running)."""


def blocks_for(contingency: Contingency | None, blocks: tuple[ServiceBlock, ...]) -> tuple[ServiceBlock, ...]:
    """The blocks as the lease book schedules them: a contingency that does not halt when the link comes back
    (SmartRTL) keeps its block running through LINK_REGAINED."""
    if contingency is None or contingency.halts_on_regain:
        return blocks
    return tuple(replace(b, halt_on_regain=False) for b in blocks)


FOLLOWER = FollowerConfig()  # the turn rate a return's follower asks for at most: the standoff's turns stay within it


class ReturnDriver:
    """Drives the current return-service lease: the plan's block through the auto-return service, or the
    injected contingency. Mutable: it holds the running block's service state between ticks."""

    def __init__(self, vehicle: Onboard) -> None:
        self.vehicle = vehicle  # its ``contingency`` (None: the plan's service) may be swapped between runs
        self.service: ServiceState | None = None  # the running block's state (None: no block started)
        self.index: int | None = None  # the lease index that state belongs to
        self.faults = 0  # blocks ended because the service raised (each reported, never fatal)
        self.reached: list[int] = []  # plan items reached (MISSION_ITEM_REACHED), drained by the endpoint
        # the way back the chain's blocks are on (``returning.Way``): the next block of the chain resumes it
        self.way: Way | None = None
        self.way_chain: int | None = None
        self.saw_loss = False  # the running block has run with the owner's link lost
        self.approaching = False  # ... and the regain's window began to fill since: it approaches (RTL_APPROACH_SPD)
        # to its end

    def stand_down(self) -> None:
        """An operator lease is current: no block runs."""
        self.service, self.index = None, None

    def drive(self, t: float, cur: ExecutionLease, x: float, y: float, yaw: float, trail: Trail,
              estimator: Estimator, outbound_speed: float, free: FreeSpace,
              seen: Sweep | None = None) -> tuple[float, float]:
        """One tick of ``cur``, the current return-service lease: speed and yaw rate. ``free``: what the range
        sensor saw free, the corners the return may cut; ``seen``: the latest sweep's returns, which the robot's
        body keeps off (``vehicle.standoff``; an injected contingency drives as it would without returnlink)."""
        v = self.vehicle
        if v.contingency is not None:
            return self._contingency(t, cur, x, y, yaw)
        book = v.book
        link_lost = book.link.lost
        fresh = self.service is None or self.index != cur.index
        linkmap = v.linkmap
        if fresh:
            self.saw_loss = self.approaching = False
        elif self.deferred(cur, link_lost) and linkmap.reliable(x, y):
            # heard again short of the place the map vouches for, and now there: the return ends here
            v.apply(v.book.regained_here(t))
            return 0.0, 0.0
        self.saw_loss = self.saw_loss or link_lost
        # the approach speed while the owner is heard as if the link were back, and from the moment the regain's
        # window began to fill to the block's end (``LinkWatch.heard_well``)
        if not self.approaching:
            well = book.link.heard_well(t)
            self.approaching = well >= REGAIN_PACKETS
            approach = well > 0
        else:
            approach = True
        try:
            if fresh:
                step = self._begin(cur, x, y, yaw, t, trail, outbound_speed, free, approach)
            else:
                step = step_block(self.service, x, y, yaw, t, trail, v.params, link_lost, outbound_speed,
                                  slipping=estimator.slipping, linkmap=linkmap, regaining=book.link.regaining(t),
                                  free=free, approach=approach)
        except Exception as e:  # noqa: BLE001 - the return runs when nobody can restart the vehicle
            return self._fault(cur.index, e, t)
        step = self._took(step, cur, fresh, book.current_id, t)
        if step.finished is not None:
            self._finish(step, cur, link_lost, t)
            return 0.0, 0.0
        return keep_off(seen, t, x, y, yaw, step.speed, step.yaw_rate, v.params["RTL_BODY_R"], FOLLOWER.max_yaw_rate)

    def _begin(self, cur: ExecutionLease, x: float, y: float, yaw: float, t: float, trail: Trail,
               outbound_speed: float, free: FreeSpace, approach: bool) -> ServiceStep:
        """The first step of a new block: a block of the same chain resumes the way the last one was on."""
        v = self.vehicle
        book = v.book
        resume = None
        if self.way is not None and self.way_chain == cur.chain:
            resume = self.way.resumed((x, y), self.way.length)
        return start_block(cur.block, x, y, t, trail, v.params, book.link.lost, outbound_speed, v.linkmap, resume,
                           free=free, yaw=yaw, regaining=book.link.regaining(t), approach=approach)

    def _took(self, step: ServiceStep, cur: ExecutionLease, fresh: bool, current_id, t: float) -> ServiceStep:
        """The block's step taken on: its state and way kept, a new route under a new sublease (the item it
        leaves reached), and a seek past the map's place ended where a station is heard."""
        v = self.vehicle
        if fresh:
            self.index = cur.index
        route = step.state.route
        if route is not None and route.way is not None:
            self.way, self.way_chain = route.way, cur.chain
        if step.replanned and current_id is not None:
            if not fresh and self.service is not None:
                self.reached.append(self.service.items[self.service.item].seq)
            v.book, _ = v.book.issue_sublease(current_id)
        self.service = step.state
        if step.finished is None and step.state.seeking and self._station_heard(t):
            # seeking past the map's place for the owner's link, and a station is heard here: the link to the
            # ground is back (a second station of the owner's, as in the handover world), and seeking on would
            # only drive away from it
            step = replace(step, finished=ExpireReason.COMPLETED)
        return step

    def _finish(self, step: ServiceStep, cur: ExecutionLease, link_lost: bool, t: float) -> None:
        """The block ended: its last item reached if it completed, and the lease ended, by a regain here when the
        link is back and the block has done what it can."""
        v = self.vehicle
        st = step.state
        if step.finished is ExpireReason.COMPLETED and 0 <= st.item < len(st.items):
            self.reached.append(st.items[st.item].seq)
        if self.deferred(cur, link_lost):
            v.apply(v.book.regained_here(t))
        else:
            v.apply(v.book.finish(cur.index, step.finished, t))

    def _station_heard(self, t: float) -> bool:
        heard = self.vehicle.station_heard_at
        return heard is not None and t - heard <= self.vehicle.params["LNK_GOOD_S"]

    def deferred(self, cur: ExecutionLease, link_lost: bool) -> bool:
        """A block that halts on regain, has run with the link lost and runs on with it back: LINK_REGAINED came
        where the map says the link does not hold, and the block is finishing the metres to the place that does."""
        return self.saw_loss and not link_lost and cur.block is not None and cur.block.halt_on_regain

    def place_holds(self, x: float, y: float) -> bool:
        """Whether a regain may halt the running return at (x, y): yes, unless its route leads to a place the link
        map vouches for, a short finish away (two cells and the arrival radius), and (x, y) is not such a place
        (docs/architecture.md §6). Further away the link being back is worth more than the map's caution: on a
        gradual range fringe the map vouches only for places far back, and the return must not drive there."""
        st = self.service
        if self.vehicle.contingency is not None or st is None or st.route is None or not st.route.by_map:
            return True
        params = self.vehicle.params
        finish = 2.0 * params["LNK_MAP_CELL"] + params["RTL_ARRIVE_R"]
        if st.path is None or st.path.length - st.progress > finish:
            return True
        return self.vehicle.linkmap.reliable(x, y)

    def _fault(self, index: int, error: Exception, t: float) -> tuple[float, float]:
        """The return service raised: end its block as STUCK, hold still this tick, and say so."""
        v = self.vehicle
        self.faults += 1
        self.service, self.index = None, None
        v.announce(f"return service fault in lease {index}: {type(error).__name__}: {error}; "
                         f"block ended, holding")
        v.apply(v.book.finish(index, ExpireReason.STUCK, t))
        return 0.0, 0.0

    def _contingency(self, t: float, cur: ExecutionLease, x: float, y: float, yaw: float) -> tuple[float, float]:
        """The injected behaviour drives the current service lease, under a sublease of it like any return."""
        v = self.vehicle
        contingency = v.contingency
        assert contingency is not None
        if self.index != cur.index and v.book.current_id is not None:
            self.service, self.index = None, cur.index
            v.book, _ = v.book.issue_sublease(v.book.current_id)
        speed, yaw_rate, finished = contingency.drive(v, t, x, y, yaw)
        if finished is not None:
            v.apply(v.book.finish(cur.index, finished, t))
            return 0.0, 0.0
        return speed, yaw_rate

    # ----- what the running block reports ------------------------------------------------------------------
    def state(self) -> int:
        """RETURNLINK_STATE while a return-service lease is current."""
        contingency = self.vehicle.contingency
        if contingency is not None:
            return State.HOLDING if contingency.holding else State.RETURNING
        st = self.service
        if st is None or st.item < 0:
            return State.RETURNING
        command = st.items[st.item].command
        if command == NAV_LOITER_TIME:
            return State.HOLDING
        return State.NAVIGATING if command == NAV_WAYPOINT else State.RETURNING

    def displacement(self, x: float, y: float) -> float:
        """How far the running block has taken the robot from where it started."""
        return 0.0 if self.service is None else block_displacement(self.service, x, y)

    def route_remaining(self) -> float:
        st = self.service
        if st is None or st.path is None:
            return 0.0
        return max(0.0, st.path.length - st.progress)
