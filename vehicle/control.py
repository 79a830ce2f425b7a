"""The control tick, 50 times a second (docs/architecture.md §2): sensors -> estimator -> trail; the lease triggers;
the current lease's commands -> actuators.

``ControlLoop`` owns what the tick measures and builds (the estimator, the breadcrumb trail and the crumbs waiting
for their link tag, the last readings) and reads the rest from its vehicle: the lease book, the setpoint and the
arming the operator's commands left there (``vehicle/app.py``). An operator lease drives on the teleop setpoint,
checked against the lease once more at the actuator; a return-service lease is driven by ``ReturnDriver``
(``vehicle/contingency.py``). Time is an argument and the robot is reached only through its ``RobotDriver``.
"""

from __future__ import annotations

from collections import deque
from typing import Protocol

from vehicle.clearance import FreeSpace
from vehicle.contingency import Onboard, ReturnDriver
from vehicle.estimator import Estimator
from vehicle.io import Readings, RobotDriver
from vehicle.lease import ExecutionLease, Holder, Verdict
from vehicle.linkmap import LinkMap, MapConfig
from vehicle.standoff import Sweep, remember, sweep
from vehicle.teleop import Setpoint
from vehicle.trail import Crumb, Trail, TrailConfig

OUTBOUND_GAIN = 0.02  # per tick: how fast the remembered outbound speed follows the speed driven under teleop
PACE_GAIN = 0.2  # per tick: the ground speed a crumb carries, smoothed over a few ticks (odometry noise, foot slip)
OUTBOUND_MIN_STICK = 0.2  # m/s: slower setpoints (creeping, turning in place) do not teach the outbound speed


def _beams(scan) -> int:
    """How many beams a driver's scan has (0 when it is not a sequence: ``sweep`` drops such a scan anyway)."""
    try:
        return len(scan.bearings)
    except TypeError:
        return 0


class Ticking(Onboard, Protocol):
    """The vehicle as its tick reads it (``vehicle.app.Vehicle``, named here as a protocol so this module does not
    import it back): what a return sees of it (``Onboard``), and the robot, the operator's setpoint and the radio's
    report. The tick changes none of its fields: the vehicle keeps its own clock (``Vehicle.tick``), and a setpoint
    the tick finds spent is dropped by the vehicle that holds it (``drop_setpoint``)."""

    driver: RobotDriver
    setpoint: Setpoint | None  # the operator's; None once it is stale or its lease is gone

    def drop_setpoint(self) -> None:
        """The setpoint is spent (stale, its lease gone, a return drives): none drives until the operator sends one."""

    def link_good(self, t: float) -> bool:
        """The link tag of a crumb laid now."""

    def rssi_at(self, t: float) -> float:
        """The owner's signal at the robot now (dBm), nan when unknown."""


class ControlLoop:
    """One vehicle's tick. Mutable: it is the shell around the estimator and the trail."""

    def __init__(self, vehicle: Ticking, returns: ReturnDriver, pose: tuple[float, float, float], t: float) -> None:
        x, y, yaw = pose
        self.vehicle = vehicle
        self.returns = returns
        self.estimator = Estimator(x, y, yaw, t, pos_std=0.3, yaw_std=0.02)
        self.trail = Trail(TrailConfig.from_params(vehicle.params))
        self.linkmap = LinkMap(MapConfig.from_params(vehicle.params))  # the owner's link over space
        self.free = FreeSpace()  # what the range sensor saw free: the corners a return may cut
        self.sweep: Sweep | None = None  # the latest sweep's returns near the robot: what a return keeps off
        self.readings: Readings | None = None
        self._crumbs: deque[Crumb] = deque()  # recorded, waiting for their link tag to be final
        self.last_fix: tuple[float, float] | None = None  # the last fix used, for GPS_RAW_INT
        self.last_fix_t: float | None = None
        self.command_out = (0.0, 0.0)
        self.link_is_good = False  # this tick's link tag (owner heard recently, with good quality)
        self.outbound_speed = 0.0  # the speed driven outbound, for a return at RTL_SPEED 0
        self.pace = 0.0  # the ground speed now, smoothed: the crumbs carry it, for a return's pace per stretch
        self.stale_commands_executed = 0  # setpoints the actuator guard caught outside the current lease: must be 0
        # the (book, setpoint) pair the teleop guards last passed (see ``_teleop``)

    def tick(self, t: float, dt: float) -> tuple[float, float]:
        """Sensors -> estimator -> trail; lease triggers; the current lease's commands -> actuators (``dt``: the time
        since the last tick)."""
        v = self.vehicle
        r = v.driver.read(t, dt if dt > 1e-6 else 1e-6)
        self.readings = r
        est = self.estimator
        est.predict(r.speed, r.yaw_rate, t, r.accel)
        if r.heading is not None:
            est.heading(r.heading, r.heading_std)
        fix = r.fix
        if fix is not None and est.fix(fix.x, fix.y, fix.std):
            self.last_fix, self.last_fix_t = (fix.x, fix.y), t
        p = est.pose
        self.linkmap.at(t, p.x, p.y)
        if r.scan is not None:
            self.free.scan(p.x, p.y, p.yaw, r.scan)
            # (a few rangefinders' beams are kept for a moment with those before them: ``remember``)
            self.sweep = remember(self.sweep, sweep(t, p.x, p.y, p.yaw, r.scan), _beams(r.scan))
        book = v.book
        good = self.link_is_good = v.link_good(t)
        if v.contingency is not None:
            v.contingency.observe(v, t)
        self.pace += PACE_GAIN * (abs(r.speed) - self.pace)
        self._crumbs.append(Crumb(p.x, p.y, t, p.std, good, v.rssi_at(t), self.pace))  # (RSSI: nan unless fresh)

        # a regain halts a return only where the link map says the link holds (asked only while the link is lost)
        holds = not book.link.lost or self.returns.place_holds(p.x, p.y)
        out = book.tick_changes(t, holds)  # (None on most ticks: nothing happened)
        if out is not None:
            v.apply(out)
        cur = v.book.current
        # a block about to start plans from the whole trail; afterwards crumbs wait for their true tag again
        starting = cur is not None and cur.holder is Holder.RETURN_SERVICE and self.returns.index != cur.index
        self._lay_crumbs(t, flush=starting)
        speed, yaw_rate = self._control(t, cur, p.x, p.y, p.yaw)
        if not v.armed:
            speed, yaw_rate = 0.0, 0.0
        self.command_out = (speed, yaw_rate)
        v.driver.command(speed, yaw_rate)
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
        horizon = t if flush else t - self.vehicle.params["LNK_GOOD_S"]
        last = self.vehicle.book.link.last_good
        while crumbs and crumbs[0].t <= horizon:
            c = crumbs.popleft()
            good = c.link_good and last is not None and last >= c.t
            self.trail.add(c if good == c.link_good else c._replace(link_good=good))

    def _control(self, t: float, cur: ExecutionLease | None, x: float, y: float, yaw: float) -> tuple[float, float]:
        """The commands of ``cur``, the book's current lease (the tick has it in hand already)."""
        if cur is None or cur.holder is Holder.OPERATOR:
            self.returns.stand_down()
            return self._teleop(t)
        self.vehicle.drop_setpoint()
        return self.returns.drive(t, cur, x, y, yaw, self.trail, self.estimator, self.outbound_speed, self.free,
                                  self.sweep)

    def _teleop(self, t: float) -> tuple[float, float]:
        """The operator's setpoint, if it is still alive and its lease is still the current one."""
        v = self.vehicle
        sp = v.setpoint
        if sp is None:
            return 0.0, 0.0
        if t > sp.until:
            v.drop_setpoint()
            return 0.0, 0.0
        book = v.book
        # both guards run every tick the setpoint drives: a safety check is never cached (issue 29; skipping them
        # for a book and setpoint already cleared saved 1.5 % of the tick)
        if book.check(book.owner or 0, sp.lease).verdict is not Verdict.EXECUTE:
            # the lease this setpoint was sent under is gone: it must not drive the robot any more
            v.drop_setpoint()
            return 0.0, 0.0
        cur = book.current
        if cur is None or book.epoch is None or sp.lease.index != cur.index:
            # a last guard at the actuator, independent of how the setpoint got here: never drive on it
            self.stale_commands_executed += 1
            v.drop_setpoint()
            return 0.0, 0.0
        if abs(sp.speed) > OUTBOUND_MIN_STICK and self.readings is not None:
            self.outbound_speed += OUTBOUND_GAIN * (abs(self.readings.speed) - self.outbound_speed)
        return sp.speed, sp.yaw_rate
