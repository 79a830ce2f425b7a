"""The scripted operator: a person at a ground station, written as a small state machine over ``gcs``.

It only knows what a real operator's screen shows (telemetry and lease status that reached it over the radio),
never the simulator's truth: it takes control, uploads the return plan, arms, drives the route by steering the
reported position toward each waypoint, lets go of the stick when its telemetry goes stale, and when the vehicle is
back and waiting for a claim it claims the fresh lease and drives the resume route.

Like every scripted operator (``sim.station_script.ScriptedStation``, its root), it learns from a lost link: a
place it was driving toward when the link died is tried again, but after ``attempts`` losses on the way there it
gives that place up and goes on with the rest of its route.
"""

from __future__ import annotations

import math

from gcs.station import GroundStation, LeaseStatus, Pending, Transfer, VehicleView, mav
from link.mission import Item
from sim.station_script import WAYPOINT_RADIUS, Leg, ScriptedStation

STALE_TELEMETRY = 1.0  # s: an operator lets go of the stick when the picture freezes
# what ``step`` compares the vehicle's status with every tick, looked up in the dialect once
_AWAITING_CLAIM, _TELEOP = mav.RETURNLINK_STATE_AWAITING_CLAIM, mav.RETURNLINK_STATE_TELEOP
_RETURNING, _COMMS_LOST = mav.RETURNLINK_STATE_RETURNING, mav.LEASE_EXPIRE_REASON_COMMS_LOST
_SETTING_UP = frozenset(("connect", "acquiring", "uploading", "arming"))  # the phases before it drives


class Operator(ScriptedStation):
    def __init__(self, gs: GroundStation, route, resume_route, plan: list[Item], teleop: str = "velocity",
                 attempts: int = 2, rejoin: bool = True) -> None:
        super().__init__(route, resume_route, attempts, rejoin)
        self.gs = gs
        self.plan = plan
        self.teleop = teleop
        self.pending: Pending | None = None
        self.transfer: Transfer | None = None
        self.claims = 0

    def step(self, t: float) -> None:
        gs, v = self.gs, self.gs.vehicle
        st = v.status
        if self.phase in _SETTING_UP:  # one lookup on the ticks that drive (nearly all), not four comparisons
            self._set_up(t, gs, v, st)
            return
        fresh = v.last_heard is not None and t - v.last_heard < STALE_TELEMETRY
        if st is None:
            return
        if st.state == _AWAITING_CLAIM and st.owner == gs.sysid and fresh:
            self._claim(t, st)
        elif not fresh:
            self._lost_on_the_way()  # the latest sign of a loss names the place
            # the picture froze: the hand comes off the stick, and the joystick streams it at rest whatever the
            # station hears, as ground stations' joysticks do (docs/simulate.md, "The scripted station")
            gs.stop()
        elif st.state != _TELEOP or st.owner != gs.sysid:
            if st.state == _RETURNING and st.last_reason == _COMMS_LOST:
                self._lost_on_the_way()  # the vehicle lost us and is coming back
            gs.stop()
        else:
            self._drive_on()

    def _claim(self, t: float, st: LeaseStatus) -> None:
        """The vehicle is back and waits for our claim: count the loss against the place it was cut off on the way
        to, claim the fresh lease, and from here drive the way home, picked up where the return left the robot."""
        gs, v = self.gs, self.gs.vehicle
        self._count_loss()  # the link died on the way there: the vehicle came back without it
        if self.pending is None or self.pending.done:
            self.pending = gs.claim(-1)
            self.claims += 1
            self._say(t, f"claiming [{st.epoch},{st.current}]")
            if self.phase == "driving" and not self.leg.done:
                self.phase = "resuming"
            self._pick_up_way_home(v.position)  # the return moved the robot: pick the way home up from there

    def _drive_on(self) -> None:
        """Our lease, a fresh picture: drive the leg of the phase (the route, or after a claim the way home)."""
        if self.phase == "driving" and self.claims and self.leg.done:
            self.phase = "resuming"
        leg = self.resume if self.phase == "resuming" else self.leg
        if leg.done:
            self.gs.stop()
        else:
            self._drive(leg)

    def _set_up(self, t: float, gs: GroundStation, v: VehicleView, st: LeaseStatus | None) -> None:
        """Connect, take control, upload the plan, arm: one phase a tick until it drives."""
        if self.phase == "connect":
            if v.last_heard is not None and st is not None:
                self.pending = gs.acquire()
                self.phase = "acquiring"
            return
        if self.phase == "acquiring":
            if self.pending and self.pending.done:
                if self.pending.ok:
                    self._say(t, f"in control, epoch {self.pending.param2}")
                    self.transfer = gs.upload(self.plan) if self.plan else None
                    self.phase = "uploading"
                else:
                    self.phase = "connect"
            return
        if self.phase == "uploading":
            if self.transfer is None or self.transfer.done:
                if self.transfer is not None:
                    self._say(t, f"plan upload {'accepted' if self.transfer.ok else 'failed'}")
                self.pending = gs.arm(True)
                self.phase = "arming"
            return
        # arming
        if self.pending and self.pending.done:
            if self.pending.ok:
                self.phase = "driving"
            else:
                self.pending = gs.arm(True)

    def _drive(self, leg: Leg) -> None:
        gs, v = self.gs, self.gs.vehicle
        if v.position is None:
            return
        x, y, speed = leg.points[leg.index]
        place = (x, y)
        if self._given_up(place):  # lost the link on the way there often enough: give it up
            leg.index += 1
            self.heading_to = None
            if leg.done:
                gs.stop()
            return
        self.heading_to = place
        dn, de = x - v.position[0], y - v.position[1]
        d = math.hypot(dn, de)
        if d < WAYPOINT_RADIUS:
            leg.index += 1
            self.heading_to = None
            if leg.done:
                gs.stop()
            return
        s = min(speed, 0.6 * d + 0.3)
        if self.teleop == "manual":
            err = (math.atan2(de, dn) - v.yaw + math.pi) % (2 * math.pi) - math.pi
            gs.drive_manual(s / 2.0 * max(0.0, math.cos(err)), max(-1.0, min(1.0, 1.6 * err)))
        else:
            gs.drive_velocity(s * dn / d, s * de / d)
