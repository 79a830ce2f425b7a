"""The scripted operator of a companion run: a person at a ground station flying an ArduPilot rover that has
returnlink companion between its telemetry port and the radio.

It is the firmware operator (``sim.firmware.operator.FirmwareOperator``: GUIDED, arm, a position target per
waypoint to the autopilot, component 1) with the lease steps of the native operator (``sim.operator.Operator``)
in front, taken through the same ground-station library (``gcs.station.GroundStation``) addressed to the
companion, component 191: it takes control (MAV_CMD_REQUEST_OPERATOR_CONTROL), uploads the scenario's return plan,
and only then switches the autopilot to GUIDED, arms and drives. The companion forwards those to the autopilot only
while the operator's lease is current, so the operator keeps its hands off while the return holds the lease, and
when the return has ended and the vehicle waits for a claim it claims the fresh lease (MAV_CMD_LEASE_CLAIM) before
it takes the autopilot back from HOLD as the firmware operator does.

Everything it sends leaves through the station's one MAVLink encoder, so the companion sees one sequence of
packet numbers from it (its link watch counts the gaps) and one heartbeat a second.
"""

from __future__ import annotations

from gcs.station import GroundStation, mav
from link.mission import Item
from sim.firmware.operator import GCS_COMPID, GCS_SYSID, STALE_TELEMETRY, FirmwareOperator
from vehicle.companion.router import COMPANION_COMPID

_AWAITING_CLAIM, _TELEOP = mav.RETURNLINK_STATE_AWAITING_CLAIM, mav.RETURNLINK_STATE_TELEOP
_TAKING_CONTROL = frozenset(("connect", "acquiring", "uploading"))  # the lease steps before the firmware's own
STICK_PERIOD = 0.1  # s: a held stick is streamed as the native operator's is (gcs.station.TELEOP_PERIOD)
HELD_STICK = 0x05C7  # SET_POSITION_TARGET type mask: velocity and yaw rate used (all zero)


class ThroughCompanion:
    """What both companion operators (ArduPilot's here, PX4's in ``sim.px4.companion_operator``) do alike, before the
    autopilot operator's class among their bases: everything leaves through the ground station ``gs`` (one MAVLink
    encoder: one sequence of packet numbers for the companion's link watch), a scripted RTL goes to the companion,
    and control is taken the native operator's way."""

    def _send(self, msg) -> None:
        self.gs.mav.send(msg)

    def request_rtl(self, t: float) -> None:
        """A scripted RTL (the scenario's ``rtl`` event): to the companion, where it expires the operator's lease
        and the return plan takes over, as on the native vehicle."""
        self.gs.rtl()
        self._say(t, "rtl requested")

    def take_control(self, t: float, start: str, then: str, ready: bool) -> None:
        """Take control of the companion and upload the return plan, one step a tick: ``phase`` goes ``start`` ->
        acquiring (once ``ready``: the companion's status heard) -> uploading -> ``then`` (the autopilot's own
        steps), back to ``start`` if the companion refuses the lease."""
        gs = self.gs
        if self.phase == start:
            if ready:
                self.pending = gs.acquire()
                self.phase = "acquiring"
        elif self.phase == "acquiring":
            if self.pending is not None and self.pending.done:
                if self.pending.ok:
                    self._say(t, f"in control, epoch {self.pending.param2}")
                    self.transfer = gs.upload(self.plan) if self.plan else None
                    self.phase = "uploading"
                else:
                    self.phase = start
        elif self.transfer is None or self.transfer.done:
            if self.transfer is not None:
                self._say(t, f"plan upload {'accepted' if self.transfer.ok else 'failed'}")
            self.phase = then

    def claim(self, t: float, st) -> None:
        """The return has ended and the vehicle waits for the operator's claim, with its picture fresh: as the
        native operator (``sim.operator.Operator.step``) the waypoint it was driving toward counts one loss, it
        claims the fresh lease, and from here it drives the resume route, picked up where the return left the rover
        (``Leg.join``). Driving on along the way out instead took the rover straight back into the dead zone after
        every return: 7-8 losses of the link in a generated office's 170 s where the native rover has one."""
        self._count_loss()
        if self.pending is None or self.pending.done:
            self.pending = self.gs.claim(-1)
            self.claims += 1
            self._say(t, f"claiming [{st.epoch},{st.current}]")
            if self.phase == "driving" and not self.leg.done:
                self.phase = "resuming"
            self._rejoin()

    def drives_home(self) -> None:
        """A claim after the whole way out was driven still turns the operator home, as the native one turns."""
        if self.phase == "driving" and self.claims and self.leg.done:
            self.phase = "resuming"


class CompanionOperator(ThroughCompanion, FirmwareOperator):
    def __init__(self, route, resume_route, origin: tuple[float, float], plan: list[Item], attempts: int = 2,
                 sysid: int = GCS_SYSID, compid: int = GCS_COMPID, target_system: int = 1,
                 rejoin: bool = True) -> None:
        super().__init__(route, resume_route, origin, attempts, sysid, compid, target_system, rejoin)
        self.gs = GroundStation(sysid, compid, target=target_system, target_comp=COMPANION_COMPID)
        self.plan = plan
        self.pending = None  # the lease command in flight (acquire, claim)
        self.transfer = None  # the plan upload
        self.claims = 0
        self.next_stick = 0.0

    # ----- what it hears and sends -----------------------------------------------------------------------------
    def feed(self, data: bytes, t: float) -> None:
        super().feed(data, t)
        self.gs.feed(data, t)

    def tick(self, t: float) -> list[bytes]:
        st = self.gs.vehicle.status
        if self.phase in _TAKING_CONTROL:
            self._take_control(t)
        elif st is not None:
            self._follow_lease(t, st)
        return self.gs.tick(t)

    # ----- the lease steps --------------------------------------------------------------------------------------
    def _take_control(self, t: float) -> None:
        self.take_control(t, "connect", "guided",  # the firmware operator's steps next (the companion streams)
                     self.gs.vehicle.status is not None)

    def _follow_lease(self, t: float, st) -> None:
        """Drive while the operator's lease is current; claim the fresh one after a return; else hands off."""
        gs = self.gs
        mine = st.owner == gs.sysid
        if st.state == _AWAITING_CLAIM and mine:
            if gs.vehicle.last_heard is not None and t - gs.vehicle.last_heard < STALE_TELEMETRY:
                self.claim(t, st)
            return
        if st.state == _TELEOP and mine:
            self.drives_home()
            self._step(t)
            return
        # the return holds the lease: what was being driven toward counts as cut off; the operator holds its stick
        # still and the joystick streams it at rest whatever the station hears, as the native station's does
        # (``gcs.station.GroundStation.stop``): a zero-velocity target to the autopilot at 10 Hz, which the
        # companion refuses under the return's lease but hears, so a regain is judged on the same stream for every
        # robot (a heartbeat alone is three seconds of packets for the three a regain needs)
        self._lost_on_the_way()
        self.sent_target = None
        if t >= self.next_stick:
            self.next_stick = t + STICK_PERIOD
            self._send(mav.MAVLink_set_position_target_local_ned_message(
                0, self.target, 1, mav.MAV_FRAME_BODY_NED, HELD_STICK, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0))
