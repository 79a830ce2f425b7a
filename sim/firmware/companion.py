"""``returnlink sim run SCENARIO --vehicle ardurover --policy companion``: returnlink companion beside the real
ArduPilot Rover firmware, in the scenario's world (docs/architecture.md §10-§11).

The firmware flies in lockstep exactly as for its own failsafes (``FirmwareRun``), and the companion
(``vehicle.companion.app.Companion``, the very object ``returnlink companion`` runs) sits between the radio model
and the firmware's MAVLink port, as it would sit between a telemetry radio and the autopilot's TELEM port: what the
firmware says reaches the companion, which relays it and its own frames (LEASE_STATUS, LEASE_EVENT, ...) to the
ground through the radio; what the radio delivers from the stations reaches the companion, which passes to the
firmware only what the lease allows. Same seeds, same jams, same RADIO_STATUS as every other policy. It ticks at
50 Hz on simulated time, after the radio has delivered in each tick; its frames to the firmware go out at once
(the firmware waits for its physics answer meanwhile, so which of its loops sees them never depends on timing),
its frames to the ground leave through the radio with the next tick's.

The telemetry radio has two ends here as on a real rover: the operator's reports to its ground station (as for every
policy), and the vehicle-side radio on the companion's ground port, which injects RADIO_STATUS once a second as a
SiK radio does, its ``rssi`` the operator station's signal at the robot (the radio model's channel, quantised to
SiK units by ``link.proxy.RadioReport``). The companion reads it as it would read a real radio's
(``vehicle.radio_status``): the link map's ``rssi_dbm`` and the crumbs' RSSI. Like the native runner, which feeds
its vehicle the same channel at the same moments (``sim.runner.Run._radio_status``), the radio reports nothing
while the operator's station is dead or jammed. ``linkmap.csv`` is the companion's map (``sim.outputs``), in the
autopilot's local frame (x north, y east from the scenario's start, ``frame_offset``), as the vehicle knows it.

The companion's returnlink parameters are the native vehicle's: the defaults with the scenario's own on top. The
firmware's are those of ``firmware_params("companion")``: its GCS failsafe on with Hold as the backstop, the rest
of what ``returnlink companion --check`` asks for.

The record is the native runner's (``sim.lease_record``) beside the firmware's own rows, so the metrics mean what
they mean for the native vehicle (``sim.firmware.companion_metrics``). The companion's vehicle works in the
autopilot's local frame, whose origin is the scenario's start (``frame_offset``); the record keeps positions in
the true frame. Before the companion has booted (it waits for the autopilot's first position estimate, a fraction
of a second into the run) the trace's estimate is the firmware's own.
"""

from __future__ import annotations

import math
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

from gcs.plans import from_plan_items
from link.proxy import RadioReport
from sim.firmware.companion_operator import CompanionOperator
from sim.firmware.run import FirmwareRun
from sim.lease_record import LeaseRecord
from sim.policies import COMPANION_POLICY
from sim.runner import Trace
from sim.scenario import Scenario
from vehicle.companion import router
from vehicle.companion.app import Companion
from vehicle.lease import Holder
from vehicle.lease_terms import State
from vehicle.params import load_defaults

# what a forwarded frame needs to be audited: it changes the robot's state under a lease
_AUDITED = frozenset((router.Authority.LEASE, router.Authority.MODE))
_COMPID_AT = {0xFD: 6, 0xFE: 4}  # MAVLink 2 / 1 start byte -> the byte that holds the sender's component id
AIR_RADIO = "radio"  # the source the vehicle-side radio's frames come from, on the companion's ground side


class CompanionRun(LeaseRecord, FirmwareRun):
    """One scenario flown by the firmware with returnlink companion on its telemetry port (see the module
    docstring). ``companion`` is the companion; ``vehicle`` its vehicle once booted."""

    policies = (COMPANION_POLICY,)

    def __init__(self, scenario: Scenario, seed: int | None = None, policy: str = COMPANION_POLICY,
                 firmware: Path | None = None, progress: bool = False, duration: float | None = None,
                 log_path: Path | None = None) -> None:
        super().__init__(scenario, seed, policy, firmware, progress, duration, log_path)
        params = load_defaults()
        for k, v in scenario.params.items():
            params.set(k, v)
        self.to_ground: list[bytes] = []
        self.companion = Companion(params, self._to_autopilot, self.to_ground.append, seed=self.seed, pivots=True,
                                   autopilot_name="the ArduPilot firmware")
        self.frame_offset = self.origin  # the companion's frame (the autopilot's local NED) in the true frame
        self.trace = Trace()
        self._rows = self.rows
        self._start_record()
        self._parser = apm.MAVLink(None, 0, 0)
        self._parser.robust_parsing = True
        self.forwarded = 0  # ground frames the companion passed to the firmware
        self.air_radio = RadioReport()  # the vehicle-side telemetry radio: its own sequence numbers

    def _make_operator(self, sc: Scenario) -> CompanionOperator:
        return CompanionOperator(sc.route, sc.resume_route, self.origin, from_plan_items(sc.plan), sc.attempts,
                                 sysid=sc.station(sc.operator_station).sysid)

    @property
    def vehicle(self):
        """The companion's ``Vehicle`` (None until it has booted on the autopilot's estimate)."""
        return self.companion.vehicle

    # ----- the vehicle's side of the radio: the companion ------------------------------------------------------
    def _vehicle_frames(self, t: float) -> list[bytes]:
        """The firmware's frames to the companion; what the companion sends the ground, through the radio."""
        for data in self.link.drain(t):
            self.companion.from_autopilot(data, t)
        out = list(self.to_ground)
        self.to_ground.clear()
        return out

    def _vehicle_receive(self, data: bytes, src: str, t: float) -> None:
        self.companion.from_ground(data, t, src)
        if src == self.op_station.name:
            self.heard.append(t)

    def _vehicle_tick(self, t: float) -> None:
        v = self.vehicle
        before = self._vehicle_state(v) if v is not None else None
        self.companion.tick(t)
        if before is not None:
            self._vehicle_ticked(v, t, before)

    def _radio_status(self, t: float) -> None:
        """The ground-side report as for every policy, and the vehicle-side radio's RADIO_STATUS to the companion,
        straight onto its ground port (the radio sits on the robot: no radio hop, no loss)."""
        super()._radio_status(t)
        op = self.op_station
        if op.alive and op.state is not None and not self._jammed(op.name, t):
            self.companion.from_ground(self.air_radio.frame(op.state), t, AIR_RADIO)

    def _to_autopilot(self, data: bytes) -> None:
        """The companion's wire to the firmware; a ground frame it forwards is audited on the way."""
        at = _COMPID_AT.get(data[0]) if data else None
        if at is not None and len(data) > at and data[at] != router.COMPANION_COMPID:
            self.forwarded += 1
            self._audit_forwarded(data)
        self.link.send(data)

    def _audit_forwarded(self, data: bytes) -> None:
        """An independent check of the router, as the native runner's audit checks the vehicle's guard: a forwarded
        frame that drives the robot or changes its mode must come from the owner while the lease last announced
        (LEASE_EVENT) is an operator's."""
        v = self.vehicle
        if v is None or not v.event_log:
            return
        for m in self._parser.parse_buffer(data) or ():
            if m.get_type() == "BAD_DATA" or router.authority(m) not in _AUDITED:
                continue
            if v.event_log[-1].holder is not Holder.OPERATOR or m.get_srcSystem() != v.book.owner:
                self.audit_stale += 1

    # ----- events that mean something to the companion ---------------------------------------------------------
    def _event(self, ev, t: float) -> None:
        """A lease claim or a parameter change reaches the companion through the operator's station; the rest as
        for the firmware's own failsafes."""
        if ev.action in ("claim", "param") and (ev.station or self.scenario.operator_station) == self.op_station.name:
            if ev.action == "claim":
                self.operator.gs.claim(-1)
            else:
                self.operator.gs.param_set(ev.name, ev.value)
            return
        super()._event(ev, t)

    # ----- recording -------------------------------------------------------------------------------------------
    def _record(self, t: float, pos: tuple[float, float]) -> None:
        super()._record(t, pos)
        link, rssi = self.rows[-1][6], self.rows[-1][7]
        v = self.vehicle
        ox, oy = self.frame_offset
        if v is None:
            est = self.link.tap.estimate
            ex, ey = (ox + est[0], oy + est[1]) if est is not None else (math.nan, math.nan)
            self.trace.rows.append((t, pos[0], pos[1], ex, ey, 0, -1, State.NO_OWNER, link, rssi, False, 0.0, 0.0))
            return
        p = v.estimator.pose
        cur = v.book.current
        if cur is None:
            holder, index, returning = 0, -1, False
        else:
            holder, index, returning = int(cur.holder), cur.index, cur.holder is Holder.RETURN_SERVICE
        speed, yaw_rate = v.command_out
        self.trace.rows.append((t, pos[0], pos[1], ox + p.x, oy + p.y, holder, index, v.state(), link, rssi,
                                v.link_is_good, speed, yaw_rate))
        self._track_block(v, t, pos, cur, returning)

    def run(self) -> CompanionRun:
        super().run()
        if self.vehicle is not None:
            self._close_block()
        return self


def firmware_run(scenario: Scenario, seed: int | None, policy: str, firmware: Path, **options) -> FirmwareRun:
    """The run that flies ``policy`` on the firmware: its own failsafe (``FirmwareRun``), or returnlink companion
    beside it (``CompanionRun``). Here, not in ``sim.firmware.run``: the one module that knows both classes."""
    if policy == COMPANION_POLICY:
        return CompanionRun(scenario, seed, firmware=firmware, **options)
    return FirmwareRun(scenario, seed, policy, firmware, **options)
