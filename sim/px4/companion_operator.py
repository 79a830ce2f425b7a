"""The scripted operator of a PX4 companion run: a person at a ground station flying a PX4 rover that has returnlink
companion between its telemetry port and the radio (docs/architecture.md §11.2).

It is the PX4 operator (``sim.px4.operator.PX4Operator``: Offboard setpoints streamed at 10 Hz to PX4,
component 1) with the lease steps of the ArduPilot companion operator (``sim.firmware.companion_operator``) in
front, taken through the same ground-station library addressed to the companion, component 191: it takes control
(MAV_CMD_REQUEST_OPERATOR_CONTROL), uploads the scenario's return plan, and only then asks PX4 for its position
stream, arms and switches to Offboard. The companion forwards those to PX4 only while the operator's lease is
current. While the return holds the lease the operator keeps streaming a setpoint where the rover stands (refused
by the companion, but heard: the regain is judged on the same stream for every robot); once the return has ended
and the vehicle waits for a claim it claims the fresh lease and takes PX4 back from Hold as the PX4 operator does
after PX4's own failsafe (a target where the rover stands, Offboard, then the resume route).

PX4 leaves Offboard for Hold by itself when the operator's stream has been silent for COM_OF_LOSS_T, and the
companion's dead-man asks for Hold after LNK_HOLD_S of the owner's silence: both happen in a radio hole too short to
lose the lease. The operator still owns the rover then, and its stream (which never stopped on its side) has the
companion switch PX4 back to Offboard on the same target; the hole does not count as a loss of the waypoint.
"""

from __future__ import annotations

from gcs.station import GroundStation, mav
from link.mission import Item, Origin
from sim.firmware.companion_operator import ThroughCompanion
from sim.firmware.operator import GCS_COMPID, GCS_SYSID, RETRY_S
from sim.px4.lockstep import HOLD, OFFBOARD
from sim.px4.operator import PX4Operator
from vehicle.companion.router import COMPANION_COMPID

_AWAITING_CLAIM, _TELEOP = mav.RETURNLINK_STATE_AWAITING_CLAIM, mav.RETURNLINK_STATE_TELEOP
_TAKING_CONTROL = frozenset(("lease", "acquiring", "uploading"))  # the lease steps before the PX4 operator's own
_DRIVING = frozenset(("driving", "resuming"))
HOLD_WAIT_S = 3.0  # s of a Hold in the operator's own drive before it switches back to Offboard itself


class PX4CompanionOperator(ThroughCompanion, PX4Operator):
    """The PX4 operator behind returnlink companion (see the module docstring)."""

    def __init__(self, route, resume_route, geo: Origin, plan: list[Item], attempts: int = 2,
                 sysid: int = GCS_SYSID, compid: int = GCS_COMPID, rejoin: bool = True) -> None:
        super().__init__(route, resume_route, geo, attempts, sysid, compid, rejoin)
        # PX4's system id (its instance + 1) is learnt from its HEARTBEAT: the station is pointed at it then
        self.gs = GroundStation(sysid, compid, target=0, target_comp=COMPANION_COMPID)
        self.plan = plan
        self.phase = "lease"
        self.pending = None  # the lease command in flight (acquire, claim)
        self.transfer = None  # the plan upload
        self.claims = 0
        self.returned = False  # a return held the lease since the operator last drove
        self.held_since: float | None = None  # since when its own drive stands in Hold

    # ----- what it hears and sends -----------------------------------------------------------------------------
    def feed(self, data: bytes, t: float) -> None:
        super().feed(data, t)
        if self.target and self.gs.target != self.target:
            self.gs.target = self.target
        self.gs.feed(data, t)

    def tick(self, t: float) -> list[bytes]:
        st = self.gs.vehicle.status
        if self.phase in _TAKING_CONTROL:
            self._take_control(t)
        elif st is not None:
            self._follow_lease(t, st)
        self._stream(t)
        return self.gs.tick(t)

    # ----- the lease steps --------------------------------------------------------------------------------------
    def _take_control(self, t: float) -> None:
        gs = self.gs
        self.take_control(t, "lease", "connect",  # the PX4 operator's steps next
                     bool(gs.target) and gs.vehicle.status is not None)

    def _follow_lease(self, t: float, st) -> None:
        """Drive while the operator's lease is current; claim the fresh one after a return; else hands off."""
        gs = self.gs
        mine = st.owner == gs.sysid
        if st.state == _AWAITING_CLAIM and mine:
            if self.fresh(t):
                self.claim(t, st)
            return
        if st.state == _TELEOP and mine:
            if not self.returned and self.phase in _DRIVING and self.armed and self.mode == HOLD:
                # PX4's Offboard loss or the companion's dead-man in a radio hole: the rover is still ours, and the
                # stream (never stopped on this side) has the companion switch it back to Offboard. Only a Hold
                # that outlasts HOLD_WAIT_S with a fresh picture is the operator's to end itself: a mode change on
                # a stale picture would take the lease from a return begun meanwhile (NEWER_LEASE)
                self.held_since = t if self.held_since is None else self.held_since
                if t - self.held_since >= HOLD_WAIT_S and self.fresh(t) and t >= self.next_retry:
                    self.next_retry = t + RETRY_S
                    self._say(t, "back to offboard after a hold")
                    self._set_mode(OFFBOARD)
                return
            self.held_since = None
            self.drives_home()
            self._step(t)
            if self.phase == "offboard":
                self.returned = False  # taken back (``_after_failsafe``): from here the operator drives again
            return
        # the return holds the lease: what was being driven toward counts as cut off; the stream goes on, aimed
        # where the rover stands (refused by the companion, heard all the same)
        self.returned = True
        self._lost_on_the_way()
        self.sent_target = None
        if self.position is not None:
            self.setpoint = ("position", *self.position)
