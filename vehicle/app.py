"""The vehicle: its command authority over the lease book, the parts it is made of, and the real-time shell.

``Vehicle`` is everything onboard except MAVLink framing, and provides the one port every room outside it talks
through (``vehicle.port.VehiclePort``: the command authority, a status snapshot per tick, the event queue);
``vehicle.endpoint.Endpoint`` translates messages into its methods. It is the command authority: every
state-changing request (take or give up the root, claim or expire a lease, arm, hold, teleop, a return plan) is
decided by the lease book and its effect kept, with what the endpoint must announce (``vehicle.authority``, which
``Vehicle`` extends; a parameter is set here, as it reaches the parts too). It is made of

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

from vehicle.authority import Authority
from vehicle.contingency import Contingency, ReturnDriver
from vehicle.control import ControlLoop
from vehicle.io import RobotDriver
from vehicle.lease import Holder, LeaseConfig, LeaseEvent
from vehicle.lease_terms import State
from vehicle.linkmap import MapConfig
from vehicle.params import Params
from vehicle.port import DT, NOTHING, Announcements, Crumbs, Status
from vehicle.radio_status import STALE_S as RSSI_STALE_S
from vehicle.service import default_plan
from vehicle.teleop import MAX_TELEOP_SPEED, MAX_TELEOP_YAW_RATE, SETPOINT_TTL, Setpoint, velocity_to_command

__all__ = ["DT", "MAX_TELEOP_SPEED", "MAX_TELEOP_YAW_RATE", "SETPOINT_TTL", "Contingency", "Setpoint", "State",
           "Vehicle", "run", "velocity_to_command"]


class Vehicle(Authority):
    """The onboard state machine around the pure parts: the command authority over the lease book
    (``vehicle.authority.Authority``), the parts that act on it, the snapshot and the link as heard. Mutable.

    It provides ``vehicle.port.VehiclePort``; nothing outside the core changes its fields."""

    def __init__(self, driver: RobotDriver, params: Params, pose: tuple[float, float, float], t: float = 0.0,
                 seed: int = 0, boot_epoch: int | None = None, contingency: Contingency | None = None,
                 on_epoch: Callable[[int], str | None] | None = None) -> None:
        """``boot_epoch``: the first epoch to issue, drawn at boot by a real-time vehicle (``vehicle.epochs``);
        None derives it from ``seed``, as only the lockstep simulator may (§3.1). ``contingency``: a link-loss
        behaviour to fly instead of the return plan (the simulator's baselines); ``on_epoch``: told of each epoch
        issued, before anyone hears of it."""
        self.driver = driver
        self.home = (pose[0], pose[1])
        self.t = t
        super().__init__(params, seed, contingency, boot_epoch, on_epoch)
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
        dt = t - self.t
        self.t = t
        out = self.control.tick(t, dt)
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
                and s.block is svc and s.armed == self.armed and s.holding == self.holding
                and s.setpoint is self.setpoint and s.commands_rejected == self.commands_rejected):
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
            self.returns.route_remaining() if running else 0.0, c.trail.count, self.returns.index, self.setpoint,
            self.commands_rejected, c.stale_commands_executed)
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

    def crumbs(self) -> Crumbs:
        """The breadcrumb trail's points, times and link tags (estimate frame), oldest first: copies."""
        trail = self.trail
        return Crumbs(trail.points(), trail.times(), trail.link_good())

    def log(self, since: int = 0) -> tuple[LeaseEvent, ...]:
        """Every lease transition since boot from the ``since``-th on (never drained)."""
        log = self.event_log
        return tuple(log[since:]) if since < len(log) else ()

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
