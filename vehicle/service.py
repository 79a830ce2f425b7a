"""The auto-return service: executes the blocks of the return plan while their lease is current (docs/architecture.md
§6).

The return plan is an ordinary mission: MAV_CMD_LEASE_BOUNDARY splits it into execution leases, each holding a few
items (RETURN_TO_LINK, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH = retrace the whole trail, NAV_WAYPOINT). The service
is a pure step function: given its state, the estimated pose and the time, it returns the next state, a speed and
yaw-rate request, and, when the block is over, why (COMPLETED, TIMEOUT or STUCK) for the lease book.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from link.plan_items import (  # the MAV_CMD numbers of the items a plan may hold
    LEASE_BOUNDARY,
    LOCAL_FRAMES,
    MISSION_FRAME,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_RETURN_TO_LINK,
    NAV_WAYPOINT,
    check_fields,
)
from vehicle.clearance import FreeSpace
from vehicle.lease import ExpireReason, ServiceBlock
from vehicle.linkmap import LinkMap
from vehicle.navigation import FollowCommand, FollowerConfig, Path, follow
from vehicle.params import Params
from vehicle.returning import LINK_TAG_LAG_S, SPEED_RANGE, Route, Target, Way, continue_from, plan_route, truncate
from vehicle.trail import Trail

SUPPORTED = (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, NAV_RETURN_TO_LINK)


@dataclass(frozen=True)
class PlanItem:
    """One mission item of the return plan, in its MAV_CMD form (x north, y east in metres for waypoints)."""

    command: int
    param1: float = 0.0
    param2: float = 0.0
    param3: float = -1.0
    param4: float = -1.0
    x: float = 0.0
    y: float = 0.0
    seq: int = -1  # position in the uploaded mission, for MISSION_CURRENT / MISSION_ITEM_REACHED


def blocks_from_items(items: list[PlanItem] | tuple[PlanItem, ...], params: Params) -> tuple[ServiceBlock, ...]:
    """Split a mission at LEASE_BOUNDARY items into service blocks (one execution lease each).

    Raises ValueError naming the first unsupported item or field out of range (``link.plan_items``), so the
    mission protocol can refuse the upload whole, and no item reaches the service that it cannot run.
    """
    blocks: list[ServiceBlock] = []
    current: list[PlanItem] = []
    for k, it in enumerate(items):
        if it.command == LEASE_BOUNDARY:
            if current:
                blocks.append(_block(current, params))
            current = []
            continue
        if it.command not in SUPPORTED:
            raise ValueError(f"item {k}: command {it.command} is not supported in a return plan")
        frame = LOCAL_FRAMES[0] if it.command == NAV_WAYPOINT else MISSION_FRAME  # x/y are local metres here
        fault = check_fields(it.command, frame, (it.param1, it.param2, it.param3, it.param4, it.x, it.y, 0.0))
        if fault is not None:
            raise ValueError(f"item {k}: {fault.message}")
        current.append(replace(it, seq=k))
    if current:
        blocks.append(_block(current, params))
    return tuple(blocks)


def _block(items: list[PlanItem], params: Params) -> ServiceBlock:
    halt = True
    for it in items:
        if it.command == NAV_RETURN_TO_LINK:
            act = it.param4 if it.param4 >= 0 else params["RTL_REGAIN_ACT"]
            halt = halt and act == 0
    return ServiceBlock(tuple(items), halt_on_regain=halt)


def default_plan(params: Params) -> tuple[ServiceBlock, ...]:
    """With no plan uploaded: one RETURN_TO_LINK block with the parameter values."""
    return blocks_from_items([PlanItem(NAV_RETURN_TO_LINK)], params)


@dataclass(frozen=True)
class ServiceState:
    items: tuple[PlanItem, ...]
    item: int
    started_at: float
    item_started_at: float
    start: tuple[float, float]  # where the block started (displacement is measured from here)
    route: Route | None
    path: Path | None
    progress: float
    speed: float
    max_displacement: float
    best_remaining: float
    last_progress_at: float
    stretch_speed: bool = False  # RTL_SPEED=0: drive each stretch at the speed it was driven outbound
    onward: bool = False  # went on past a dead-zone target (docs/architecture.md §6): the next arrival ends the block
    reverse: bool = False  # the navigator is driving the route backward (it lay behind the robot)
    seeking: bool = False  # gone on past the place the link map vouched for, the link still down: at approach speed


RETURN_SPEED_MIN, RETURN_SPEED_MAX = SPEED_RANGE  # m/s: within the robot's limits (MAX_TELEOP_SPEED)


@dataclass(frozen=True)
class ServiceStep:
    state: ServiceState
    speed: float
    yaw_rate: float
    finished: ExpireReason | None = None
    replanned: bool = False  # a new route was planned: the caller issues a new sublease for it


STUCK_AFTER = 15.0  # s without getting closer to the end of the route


def start(block: ServiceBlock, x: float, y: float, t: float, trail: Trail, params: Params, link_lost: bool,
          outbound_speed: float, linkmap: LinkMap | None = None, resume: Way | None = None,
          free: FreeSpace | None = None, yaw: float | None = None, regaining: bool = False,
          approach: bool = False) -> ServiceStep:
    """Start a block. ``linkmap``: where the link reliably held (targets, docs/architecture.md §6); ``resume``: the
    way back the previous block of this chain was on, which a RETURN_TO_LINK with the link still lost picks up;
    ``yaw`` (the robot's heading), ``regaining`` and ``approach`` (as for ``step``): the route is driven from this
    tick (without ``yaw``, this tick commands a stop and the next drives)."""
    items: tuple[PlanItem, ...] = block.payload
    st = ServiceState(items, -1, t, t, (x, y), None, None, 0.0, 0.0, 0.0, math.inf, t)
    return _next_item(st, x, y, t, trail, params, link_lost, outbound_speed, linkmap, resume, free, yaw, regaining,
                      approach)


def _next_item(st: ServiceState, x: float, y: float, t: float, trail: Trail, params: Params, link_lost: bool,
               outbound_speed: float, linkmap: LinkMap | None = None, resume: Way | None = None,
               free: FreeSpace | None = None, yaw: float | None = None, regaining: bool = False,
               approach: bool = False) -> ServiceStep:
    """The block's next item begun: its route planned and, with ``yaw``, driven from this same tick."""
    k = st.item + 1
    if k >= len(st.items):
        return ServiceStep(st, 0.0, 0.0, ExpireReason.COMPLETED)
    it = st.items[k]
    speed = params["RTL_SPEED"] or outbound_speed or 1.0
    route: Route | None = None
    max_disp = params["RTL_MAX_DISP"]
    if it.command == NAV_RETURN_TO_LINK:
        route, speed, max_disp = _return_to_link(it, st, x, y, trail, params, link_lost, outbound_speed, speed,
                                                 max_disp, linkmap, resume, free)
    elif it.command == NAV_RETURN_TO_LAUNCH:
        route = plan_route(trail, (x, y), Target.ORIGIN, math.inf, link_lost, free=free,
                           clearance=params["RTL_CUT_CLR"])
        max_disp = math.inf
    elif it.command == NAV_WAYPOINT:
        route = Route(np.array([[x, y], [it.x, it.y]]), (it.x, it.y), -1, False)
        max_disp = math.inf
    path = Path(route.points) if route is not None and len(route.points) >= 2 else None
    st = replace(st, item=k, item_started_at=t, route=route, path=path, progress=0.0, speed=speed,
                 max_displacement=max_disp, best_remaining=math.inf, last_progress_at=t,
                 stretch_speed=_stretches(it, route, params), onward=False, seeking=False)
    if yaw is None or path is None:
        return ServiceStep(st, 0.0, 0.0, replanned=True)
    return _first_move(st, x, y, yaw, t, params, link_lost, regaining, approach)


def _return_to_link(it: PlanItem, st: ServiceState, x: float, y: float, trail: Trail, params: Params,
                    link_lost: bool, outbound_speed: float, speed: float, max_disp: float, linkmap: LinkMap | None,
                    resume: Way | None, free: FreeSpace | None) -> tuple[Route, float, float]:
    """A RETURN_TO_LINK item's (route, speed, displacement limit): its own limit, speed and target where it gives
    them (param1..3), else the parameters'."""
    max_disp = it.param1 if it.param1 > 0 else max_disp
    speed = it.param2 if it.param2 > 0 else speed
    target = Target(int(it.param3)) if it.param3 >= 0 else Target(int(params["RTL_TARGET"]))
    # the displacement budget is measured from where the block started
    remaining = max(0.0, max_disp - math.hypot(x - st.start[0], y - st.start[1]))
    # past the target crumb by the arrival radius (arrival then means reaching it) and by the distance the
    # tag lags behind the link: the quality behind it averages over LINK_TAG_LAG_S of outbound driving
    overshoot = params["RTL_ARRIVE_R"] + (outbound_speed or speed) * LINK_TAG_LAG_S
    # a place the map vouches for: past its edge by the arrival radius and half a cell, so the robot stops
    # inside the place that holds, not on its fringe
    depth = params["RTL_ARRIVE_R"] + 0.5 * params["LNK_MAP_CELL"]
    route = plan_route(trail, (x, y), target, remaining, link_lost, heading=math.radians(it.x),
                       overshoot=overshoot, linkmap=linkmap, resume=resume if link_lost else None,
                       map_depth=depth, map_seek=params["LNK_MAP_SEEK"], free=free,
                       clearance=params["RTL_CUT_CLR"])
    if target is not Target.HEADING:
        route = _bounded_from(route, st.start, max_disp)
    return route, speed, max_disp


def _stretches(it: PlanItem, route: Route | None, params: Params) -> bool:
    """Whether the route's own speeds set the pace: a return with no speed of its own (neither RTL_SPEED nor the
    item's param2) on a route that carries speeds."""
    own_speed = it.command == NAV_RETURN_TO_LINK and it.param2 > 0
    return (params["RTL_SPEED"] == 0 and not own_speed and route is not None and route.speeds is not None
            and it.command in (NAV_RETURN_TO_LINK, NAV_RETURN_TO_LAUNCH))


def _first_move(st: ServiceState, x: float, y: float, yaw: float, t: float, params: Params, link_lost: bool,
                regaining: bool, approach: bool = False) -> ServiceStep:
    """A route just planned, driven from the tick it was planned in: the follower's first command on it.

    Why: a block that drove only from the next tick started 20 ms behind a baseline that drives at once, 1.5 cm at
    walking pace and kept all the way, and at the sharp edge of a wall's radio shadow 1.5 cm decides whether a
    telemetry packet is heard or the station waits for the next one 0.25 s later (the mine runs that showed it:
    docs/evidence.md, "The measurements behind the vehicle's code")."""
    cmd = _follow(st, x, y, yaw, FollowerConfig.from_params(params), link_lost, regaining,
                  _approach_cap(st, params, approach))
    if cmd.arrived:  # there already: the next tick's step handles the arrival, as for any route
        return ServiceStep(st, 0.0, 0.0, replanned=True)
    st = replace(st, progress=cmd.progress, reverse=cmd.reverse, best_remaining=cmd.remaining, last_progress_at=t)
    return ServiceStep(st, cmd.speed, cmd.yaw_rate, replanned=True)


def _follow(st: ServiceState, x: float, y: float, yaw: float, cfg: FollowerConfig, link_lost: bool,
            regaining: bool, cap: float = 0.0) -> FollowCommand:
    """The follower's command on the block's route from where it got to, no faster than ``cap`` (0: no cap). With
    the link down and a way on past the target, the target is a waypoint, not a stop: no easing into it."""
    through = link_lost and not regaining and _may_go_on(st)
    speed = cruise(st)
    return follow(st.path, x, y, yaw, st.progress, min(speed, cap) if cap > 0 else speed, cfg, st.reverse, through)


def _approach_cap(st: ServiceState, params: Params, approach: bool) -> float:
    """RTL_APPROACH_SPD while the owner is heard again during a return (``approach``) or while it seeks on past the
    place the link map vouched for (0: no cap). Why (DESIGN §6.2): LINK_REGAINED comes LNK_REGAIN_S after the first
    packet at the earliest, and the robot brakes from whatever speed it then has: at 2 m/s that was 2 m of window and
    1.3 m of braking past the range's edge; at 1 m/s it is 1 m and 0.3 m."""
    return params["RTL_APPROACH_SPD"] if approach or st.seeking else 0.0


def cruise(st: ServiceState) -> float:
    """The speed to drive now: the block's fixed speed, or (RTL_SPEED=0) the speed this stretch of trail was
    driven outbound, within the robot's limits."""
    if not st.stretch_speed or st.route is None or st.route.speeds is None or st.path is None:
        return st.speed
    speeds = st.route.speeds
    i = int(np.searchsorted(st.path.cum, st.progress, side="right")) - 1
    v = float(speeds[min(max(i, 0), len(speeds) - 1)])
    if not math.isfinite(v):
        return st.speed
    return min(RETURN_SPEED_MAX, max(RETURN_SPEED_MIN, v))


def _may_go_on(st: ServiceState) -> bool:
    """Whether this block, arriving at its target with the link down, would go on back along the trail."""
    route = st.route
    return (st.items[st.item].command == NAV_RETURN_TO_LINK and not st.onward and route is not None
            and route.onward is not None and not route.truncated)


def _go_on(st: ServiceState, x: float, y: float, t: float, params: Params, link_lost: bool) -> ServiceState | None:
    """A RETURN_TO_LINK block at its target with the link still down goes on back along the trail, within its
    displacement budget: a link-good tag is a promise the place may not keep (docs/architecture.md §6). None: it may
    not."""
    route = st.route
    if not link_lost or not _may_go_on(st):
        return None
    search = (st.path.length if st.path is not None else 0.0) + params["RTL_ARRIVE_R"]
    nxt = _bounded_from(continue_from(route.onward, (x, y), search), st.start, st.max_displacement)
    if len(nxt.points) < 2 or nxt.length <= params["RTL_ARRIVE_R"]:
        return None
    return replace(st, route=nxt, path=Path(nxt.points), progress=0.0, best_remaining=math.inf,
                   last_progress_at=t, onward=True, seeking=route.by_map)


def _bounded_from(route: Route, center: tuple[float, float], radius: float) -> Route:
    pts, cut = truncate(route.points, center, radius)
    return replace(route, points=pts, truncated=route.truncated or cut)


def step(st: ServiceState, x: float, y: float, yaw: float, t: float, trail: Trail, params: Params,
         link_lost: bool, outbound_speed: float, slipping: bool = False,
         linkmap: LinkMap | None = None, regaining: bool = False, free: FreeSpace | None = None,
         approach: bool = False) -> ServiceStep:
    """One control tick of the current block. ``slipping``: the estimator finds the odometry inconsistent (wheels
    spinning against a wall), so the estimated progress is not real and the block ends STUCK rather than
    "arriving" at a target it never reached. ``regaining``: the link is lost but the owner is heard well again
    (LINK_REGAINED is on its way), so a block arriving at its target waits there instead of going on. ``approach``:
    the link is lost and the owner heard again since, so the block drives at RTL_APPROACH_SPD at most."""
    it = st.items[st.item]
    max_time = params["RTL_MAX_TIME"]
    if max_time > 0 and t - st.started_at >= max_time:
        return ServiceStep(st, 0.0, 0.0, ExpireReason.TIMEOUT)
    if slipping and it.command != NAV_LOITER_TIME:
        return ServiceStep(st, 0.0, 0.0, ExpireReason.STUCK)
    if it.command == NAV_LOITER_TIME:
        if t - st.item_started_at >= it.param1:
            return _next_item(st, x, y, t, trail, params, link_lost, outbound_speed, linkmap, free=free, yaw=yaw,
                              regaining=regaining, approach=approach)
        return ServiceStep(st, 0.0, 0.0)
    if st.path is None:
        return _next_item(st, x, y, t, trail, params, link_lost, outbound_speed, linkmap, free=free, yaw=yaw,
                          regaining=regaining, approach=approach)
    if st.onward and not link_lost:
        # past a dead-zone target only for want of the link: it is back (a block that continues on regain)
        return ServiceStep(st, 0.0, 0.0, ExpireReason.COMPLETED)
    cfg = FollowerConfig.from_params(params)
    cmd = _follow(st, x, y, yaw, cfg, link_lost, regaining, _approach_cap(st, params, approach))
    if cmd.arrived:
        onward = _go_on(replace(st, progress=cmd.progress), x, y, t, params, link_lost)
        if onward is not None:
            if regaining:  # the owner is heard again: wait here for LINK_REGAINED rather than drive on
                return ServiceStep(replace(st, progress=cmd.progress), 0.0, 0.0)
            # drive straight on along the way beyond, this same tick: no stop at a place that did not hold
            cap = _approach_cap(onward, params, approach)
            speed = cruise(onward)
            go = follow(onward.path, x, y, yaw, 0.0, min(speed, cap) if cap > 0 else speed, cfg, st.reverse,
                        _may_go_on(onward))
            if go.arrived:
                return ServiceStep(onward, 0.0, 0.0, replanned=True)
            return ServiceStep(replace(onward, progress=go.progress, reverse=go.reverse), go.speed, go.yaw_rate,
                               replanned=True)
        return _next_item(replace(st, progress=cmd.progress), x, y, t, trail, params, link_lost, outbound_speed,
                          linkmap, free=free, yaw=yaw, regaining=regaining, approach=approach)
    if cmd.remaining < st.best_remaining - 0.2:
        st = replace(st, best_remaining=cmd.remaining, last_progress_at=t)
    elif t - st.last_progress_at >= STUCK_AFTER:
        return ServiceStep(st, 0.0, 0.0, ExpireReason.STUCK)
    return ServiceStep(replace(st, progress=cmd.progress, reverse=cmd.reverse), cmd.speed, cmd.yaw_rate)


def displacement(st: ServiceState, x: float, y: float) -> float:
    return math.hypot(x - st.start[0], y - st.start[1])
