"""The one door into the vehicle core (docs/architecture.md §2 "Ports, not a hub").

Whoever talks to the core (the MAVLink services of ``vehicle/services/``, the companion of ``vehicle/companion/``,
the simulator's link-loss baselines in ``sim/policies/`` and its record of a run) holds a ``VehiclePort``, never the
``Vehicle`` class. The port is three small faces, each a Protocol of its own with at most 12 public members
(``tests/test_port.py`` counts them), so a part can be handed, and a test can fake, just the face it uses:

- **the command authority** (``CommandAuthority``): every state-changing request of a ground station (take or give
  up the root, claim or expire a lease, arm, hold, teleop, return, a return plan, a parameter) is a method that the
  lease book decides and that answers with a verdict (``Check``) or a reason (``str``). Nobody outside asks the book
  itself, nobody changes a field;
- **the status snapshot** (``Snapshot``): ``status()``, an immutable value of what the vehicle is and knows
  (``Status``), taken once per tick and retaken only when a command changed the lease book, the arming, the hold or
  the setpoint in between, so an answer sent between two ticks never shows a lease that is already gone; and the
  other reads (the parameters, the trail, the link map), each a copy;
- **the event queue** (``EventQueue``): what the core is told happened outside it (a frame heard, the radio's
  signal, the robot's own arming, a refusal or a key installed elsewhere, the robot taken from its hands) and what
  it has to announce (``Announcements``: the lease transitions, the notices, the plan items reached) since the
  endpoint's services last drained them. Draining is the only way they leave; ``log`` keeps every transition for an
  observer of the whole run.

``vehicle.app.Vehicle`` provides all three. This module imports only values (no part of the vehicle that could import it
back), so every room can name the port without tying itself to the core's composition.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

from vehicle.estimator import Pose
from vehicle.lease import Check, ExpireReason, LeaseBook, LeaseEvent
from vehicle.service import PlanItem, ServiceState
from vehicle.teleop import Setpoint

DT = 0.02  # the control tick: 50 Hz (the tick is ``vehicle.control.ControlLoop``; every loop that drives one uses it)


class Status(NamedTuple):
    """What the vehicle is and knows at one moment: read-only, built by the core, never changed by a reader.

    A named tuple, like ``vehicle.estimator.Pose`` and ``vehicle.io.Readings``. Every field is a plain value or an
    immutable one (the lease book is a frozen value: a transition makes a new book, so holding this one changes
    nothing in the core)."""

    t: float  # the time of the last tick
    pose: Pose  # the estimate (never ground truth: it is all a real vehicle knows)
    speed: float  # over the ground, this tick's odometry (0 before the first reading)
    yaw_rate: float  # rad/s, this tick's gyro (0 before the first reading)
    sensing: bool  # the robot has given readings (telemetry's GPS health needs one)
    fix_std: float | None  # this tick's position fix, its 1-sigma error (None: no fix this tick)
    fixes_used: int  # fixes the estimator took since boot
    last_fix: tuple[float, float] | None  # the last fix the estimator took (local frame)
    last_fix_t: float | None  # ... and when
    armed: bool
    holding: bool  # the operator asked for HOLD (AUTO_LOITER until it drives again)
    held: bool  # an injected contingency keeps the robot standing by its own rules
    state: int  # RETURNLINK_STATE (``vehicle.lease_terms.State``)
    home: tuple[float, float]  # where the vehicle booted (local frame)
    mav_type: int  # the robot's HEARTBEAT type
    book: LeaseBook  # the lease state: owner, epoch, current and scheduled leases, the owner's link watch
    link_good: bool  # this tick's link tag: the owner heard recently, with good quality
    outbound_speed: float  # the speed driven outbound (a return at RTL_SPEED 0 drives it)
    command_out: tuple[float, float]  # the speed and yaw rate commanded this tick
    block: ServiceState | None  # the running return block (None: none runs)
    displacement: float  # how far the running block has taken the robot from where it started (0: none runs)
    route_remaining: float  # metres of the running block's route still ahead (0: none)
    trail_points: int  # crumbs in the breadcrumb trail
    # what an observer of the whole run needs besides (the simulator's record, metrics and verdict)
    block_index: int | None  # the lease the running block belongs to (None: none runs)
    setpoint: Setpoint | None  # the operator's teleop setpoint in force (None: none, stale, or its lease gone)
    commands_rejected: int  # state changes refused since boot: each one answered and counted
    stale_commands: int  # setpoints the actuator's last guard caught outside the current lease: must stay 0


class Crumbs(NamedTuple):
    """The breadcrumb trail as a reader gets it: copies, oldest first, the newest crumb included (estimate frame)."""

    points: np.ndarray  # (n, 2)
    times: np.ndarray  # (n,) when each was laid
    link_good: np.ndarray  # (n,) its link tag


class Announcements(NamedTuple):
    """What the core has to announce since the last drain: a LEASE_EVENT per transition, a STATUSTEXT per notice."""

    events: tuple[LeaseEvent, ...] = ()
    notices: tuple[str, ...] = ()


NOTHING = Announcements()  # most ticks: nothing to announce


class ParamReader(Protocol):
    """The parameter table as a reader sees it (``vehicle.params.Params`` is one)."""

    def __getitem__(self, name: str) -> float: ...

    def names(self) -> list[str]: ...


class CommandAuthority(Protocol):
    """Face (a): may this sender do this now, under the current lease? Every method is a ground station's request,
    decided by the lease book, answered with a verdict (``Check``) or a reason, and every refusal is counted."""

    def refuses(self, sender: int) -> bool:
        """Someone else owns the vehicle: a state change from ``sender`` is refused (and counted)."""

    def admit(self, sender: int, compid: int, t: float) -> None:
        """A plain client's state-changing command may grant it the root (LEASE_AUTOGRANT)."""

    def verdict(self, sender: int, compid: int | None = None, t: float | None = None) -> Check:
        """What the lease rules say of a state change from ``sender`` under its last claimed lease now, without
        doing or counting anything (a companion's router forwards on EXECUTE). Given ``compid`` and ``t``, a plain
        client that LEASE_AUTOGRANT would make the owner now is answered EXECUTE under the lease it would get."""

    def operator_control(self, sender: int, compid: int, t: float, request: bool, allow_takeover: bool) -> Check:
        """MAV_CMD_REQUEST_OPERATOR_CONTROL: take the root lease (``request``, a takeover by another station
        allowed or not from then on) or give it up."""

    def claim(self, sender: int, epoch: int, index: int, t: float) -> Check: ...

    def expire(self, sender: int, epoch: int, index: int, t: float) -> Check: ...

    def rtl(self, sender: int, compid: int, t: float, items: tuple[PlanItem, ...] = ()) -> Check:
        """RTL button or mode: OPERATOR_EXPIRE of the operator lease, so the return plan runs; with ``items``
        (MAV_CMD_NAV_RETURN_TO_LINK as a command) those run now as one block, the stored plan re-armed after."""

    def take_manual(self, sender: int, compid: int, t: float) -> Check:
        """A manual mode (or HOLD) takes the operator lease back, if the sender owns the vehicle."""

    def command(self, sender: int, compid: int, t: float, payload: tuple) -> Check:
        """A standard state change under the sender's last claimed lease: ``("teleop", speed, yaw_rate)``,
        ``("hold",)`` or ``("arm", on)``."""

    def set_plan(self, items: tuple[PlanItem, ...], t: float) -> str | None:
        """The return plan uploaded (by the owner: the caller asked ``refuses``): why not, or None."""

    def set_plan_start(self, seq: int, sender: int, compid: int, t: float) -> str | None:
        """MISSION_SET_CURRENT: the return plan scheduled from item ``seq`` on; why not, or None."""

    def set_param(self, name: str, value: float) -> float:
        """Store a parameter and apply it at once (by the owner: the caller asked ``refuses``; ``ParamError``
        leaves the old value)."""


class Snapshot(Protocol):
    """Face (b): what the vehicle is and knows, read only (see ``Status``); every read is a value or a copy."""

    def status(self) -> Status:
        """The snapshot of now (see ``Status``). How many lease plan blocks are stored: ``len(status().book.plan)``."""

    @property
    def params(self) -> ParamReader:
        """The parameter table, to read (a change goes through ``CommandAuthority.set_param``)."""

    def param_values(self) -> dict[str, float]:
        """Every parameter's value now, a copy (what a .parm file keeps)."""

    def trail_points(self) -> np.ndarray:
        """The breadcrumb trail's points (estimate frame), oldest first: an (n, 2) copy."""

    def crumbs(self) -> Crumbs:
        """The breadcrumb trail's points, times and link tags (estimate frame), oldest first: copies."""

    def linkmap_cells(self) -> list:
        """The owner's link over space, cell by cell (``vehicle.linkmap``), for the file a station fetches."""


class EventQueue(Protocol):
    """Face (c): what the core is told happened outside it, and what it has to announce (see the module docstring).
    Nothing told here is a request: no verdict answers it."""

    # ----- told: what happened outside the core ----------------------------------------------------------------
    def heard(self, sysid: int, t: float, seq: int | None = None) -> None:
        """A trusted frame from ``sysid`` with sequence number ``seq``: the owner's feed its link watch."""

    def radio_rssi(self, dbm: float, t: float | None = None) -> None:
        """The vehicle's radio reports the owner's signal strength (never decides a loss or a regain)."""

    def robot_armed(self, armed: bool) -> None:
        """The robot reports its own arming (a companion's autopilot arms itself): the vehicle follows it."""

    def preempt(self, t: float, reason: ExpireReason, why: str) -> bool:
        """The robot left the vehicle's hands from outside the book (a companion's autopilot): the current lease
        and its chain end. True if a lease ended."""

    def refused(self) -> None:
        """A state change was refused outside the lease book (the signing gate, a companion's router): counted,
        as every refusal is, never silent."""

    def bind_key(self) -> None:
        """A signing key was installed: from now on the root only by an explicit signed request (§4.1)."""

    # ----- announced: drained by the endpoint, logged for an observer ------------------------------------------
    def announce(self, text: str) -> None:
        """A notice for the ground stations (STATUSTEXT), queued with the core's own."""

    def drain(self) -> Announcements:
        """The transitions and notices queued since the last drain, oldest first; the queue is empty afterwards."""

    def drain_reached(self) -> tuple[int, ...]:
        """The plan items reached since the last drain (MISSION_ITEM_REACHED), oldest first; then none."""

    def log(self, since: int = 0) -> tuple[LeaseEvent, ...]:
        """Every lease transition since boot from the ``since``-th on, oldest first: the record of an observer of the
        whole run (the simulator's), which draining never empties."""


class VehiclePort(CommandAuthority, Snapshot, EventQueue, Protocol):
    """The three faces together: what a part that needs all of them holds (the endpoint's services, the companion).
    It adds nothing of its own."""
