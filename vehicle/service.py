"""The auto-return service: executes the blocks of the return plan while their lease is current (DESIGN §6).

The return plan is an ordinary mission: MAV_CMD_LEASE_BOUNDARY splits it into execution leases, each holding a few
items (RETURN_TO_LINK, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH = retrace the whole trail, NAV_WAYPOINT). The service
is a pure step function: given its state, the estimated pose and the time, it returns the next state, a speed and
yaw-rate request, and, when the block is over, why (COMPLETED, TIMEOUT or STUCK) for the lease book.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from vehicle.lease import ExpireReason, ServiceBlock
from vehicle.navigation import FollowerConfig, Path, follow
from vehicle.params import Params
from vehicle.returning import LINK_TAG_LAG_S, Route, Target, plan_route, truncate
from vehicle.trail import Trail

# MAV_CMD numbers of the items a plan may hold
NAV_WAYPOINT = 16
NAV_LOITER_TIME = 19
NAV_RETURN_TO_LAUNCH = 20
NAV_RETURN_TO_LINK = 44002
LEASE_BOUNDARY = 44003
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

    Raises ValueError naming the first unsupported item, so the mission protocol can refuse the upload whole.
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
    reverse: bool = False  # the navigator is driving the route backward (it lay behind the robot)


@dataclass(frozen=True)
class ServiceStep:
    state: ServiceState
    speed: float
    yaw_rate: float
    finished: ExpireReason | None = None
    replanned: bool = False  # a new route was planned: the caller issues a new sublease for it


STUCK_AFTER = 15.0  # s without getting closer to the end of the route


def start(block: ServiceBlock, x: float, y: float, t: float, trail: Trail, params: Params, link_lost: bool,
          outbound_speed: float) -> ServiceStep:
    items: tuple[PlanItem, ...] = block.payload
    st = ServiceState(items, -1, t, t, (x, y), None, None, 0.0, 0.0, 0.0, math.inf, t)
    return _next_item(st, x, y, t, trail, params, link_lost, outbound_speed)


def _next_item(st: ServiceState, x: float, y: float, t: float, trail: Trail, params: Params, link_lost: bool,
               outbound_speed: float) -> ServiceStep:
    k = st.item + 1
    if k >= len(st.items):
        return ServiceStep(st, 0.0, 0.0, ExpireReason.COMPLETED)
    it = st.items[k]
    speed = params["RTL_SPEED"] or outbound_speed or 1.0
    route: Route | None = None
    max_disp = params["RTL_MAX_DISP"]
    if it.command == NAV_RETURN_TO_LINK:
        max_disp = it.param1 if it.param1 > 0 else max_disp
        speed = it.param2 if it.param2 > 0 else speed
        target = Target(int(it.param3)) if it.param3 >= 0 else Target(int(params["RTL_TARGET"]))
        # the displacement budget is measured from where the block started
        remaining = max(0.0, max_disp - math.hypot(x - st.start[0], y - st.start[1]))
        # past the target crumb by the arrival radius (arrival then means reaching it) and by the distance the
        # tag lags behind the link: the quality behind it averages over LINK_TAG_LAG_S of outbound driving
        overshoot = params["RTL_ARRIVE_R"] + (outbound_speed or speed) * LINK_TAG_LAG_S
        route = plan_route(trail, (x, y), target, remaining, link_lost, heading=math.radians(it.x),
                           overshoot=overshoot)
        if target is not Target.HEADING:
            route = _bounded_from(route, st.start, max_disp)
    elif it.command == NAV_RETURN_TO_LAUNCH:
        route = plan_route(trail, (x, y), Target.ORIGIN, math.inf, link_lost)
        max_disp = math.inf
    elif it.command == NAV_WAYPOINT:
        route = Route(np.array([[x, y], [it.x, it.y]]), (it.x, it.y), -1, False)
        max_disp = math.inf
    path = Path(route.points) if route is not None and len(route.points) >= 2 else None
    st = replace(st, item=k, item_started_at=t, route=route, path=path, progress=0.0, speed=speed,
                 max_displacement=max_disp, best_remaining=math.inf, last_progress_at=t)
    return ServiceStep(st, 0.0, 0.0, replanned=True)


def _bounded_from(route: Route, center: tuple[float, float], radius: float) -> Route:
    pts, cut = truncate(route.points, center, radius)
    return replace(route, points=pts, truncated=route.truncated or cut)


def step(st: ServiceState, x: float, y: float, yaw: float, t: float, trail: Trail, params: Params,
         link_lost: bool, outbound_speed: float, slipping: bool = False) -> ServiceStep:
    """One control tick of the current block. ``slipping``: the estimator finds the odometry inconsistent (wheels
    spinning against a wall), so the estimated progress is not real and the block ends STUCK rather than
    "arriving" at a target it never reached."""
    it = st.items[st.item]
    max_time = params["RTL_MAX_TIME"]
    if max_time > 0 and t - st.started_at >= max_time:
        return ServiceStep(st, 0.0, 0.0, ExpireReason.TIMEOUT)
    if slipping and it.command != NAV_LOITER_TIME:
        return ServiceStep(st, 0.0, 0.0, ExpireReason.STUCK)
    if it.command == NAV_LOITER_TIME:
        if t - st.item_started_at >= it.param1:
            return _next_item(st, x, y, t, trail, params, link_lost, outbound_speed)
        return ServiceStep(st, 0.0, 0.0)
    if st.path is None:
        return _next_item(st, x, y, t, trail, params, link_lost, outbound_speed)
    cfg = FollowerConfig(arrive_radius=params["RTL_ARRIVE_R"])
    cmd = follow(st.path, x, y, yaw, st.progress, st.speed, cfg, st.reverse)
    if cmd.arrived:
        return _next_item(replace(st, progress=cmd.progress), x, y, t, trail, params, link_lost, outbound_speed)
    if cmd.remaining < st.best_remaining - 0.2:
        st = replace(st, best_remaining=cmd.remaining, last_progress_at=t)
    elif t - st.last_progress_at >= STUCK_AFTER:
        return ServiceStep(st, 0.0, 0.0, ExpireReason.STUCK)
    return ServiceStep(replace(st, progress=cmd.progress, reverse=cmd.reverse), cmd.speed, cmd.yaw_rate)


def displacement(st: ServiceState, x: float, y: float) -> float:
    return math.hypot(x - st.start[0], y - st.start[1])
