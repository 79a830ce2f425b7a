"""The mission protocol as the return plan's way in (docs/architecture.md §4 "The return plan is a mission").

The transfer itself (uploads as transactions, re-requests, downloads, MISSION_ACK codes) is
``mission_transfer.MissionServer``; this service puts it on the wire and gives the lists their meaning: an upload
of mission type 0 is a state change only the owner (or a plain client the lease rules auto-grant) may make, and an
accepted one is converted to the local frame, checked field by field and scheduled as the return plan's execution
leases. MISSION_SET_CURRENT and DO_SET_MISSION_CURRENT choose where the plan starts; MISSION_ITEM_REACHED reports
its progress each tick. Fences and rally points (types 1 and 2) are stored and served back, nothing more.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from link.mission import Item, Origin, item_from_message
from link.plan_items import MISSION_INVALID_PARAM, ItemError, ItemFault, position_scale
from vehicle.port import VehiclePort
from vehicle.services.base import Outbox, Reply, Service, Source, command, handles, mav, whole
from vehicle.services.mission_transfer import ACCEPTED, DENIED, INVALID, UNSUPPORTED, MissionServer, to_plan

INT32_MAX = 2**31 - 1  # MISSION_ITEM_INT x / y
NO_SEQUENCE = -2  # DO_SET_MISSION_CURRENT with a sequence that is not a whole number: refused by the vehicle


def mission_type(m) -> int:
    """A message's mission_type (a MAVLink 2 extension field: absent means the mission)."""
    return getattr(m, "mission_type", mav.MAV_MISSION_TYPE_MISSION)


class MissionService(Service):
    """Mission transfers for one component, the return plan behind them, and the plan's progress.

    ``report(msgid, t)`` sends one telemetry message now (MISSION_CURRENT after the plan's start moved)."""

    def __init__(self, out: Outbox, vehicle: VehiclePort, origin: Origin,
                 report: Callable[[int, float], object] = lambda msgid, t: None) -> None:
        self.out = out
        self.vehicle = vehicle
        self.origin = origin
        self.report = report
        self.transfer = MissionServer(out.send, self._accept)

    def _say(self, why: str | None) -> None:
        if why:
            self.out.statustext(why, mav.MAV_SEVERITY_WARNING)

    def _allowed(self, sender: int, scomp: int, t: float) -> tuple[int, str]:
        """An upload or a clear is a state change: only the owner (or a plain client auto-granted) may."""
        v = self.vehicle
        v.admit(sender, scomp, t)
        if v.refuses(sender):
            return DENIED, f"mission from {sender} refused: GCS {v.status().book.owner} is in control"
        return ACCEPTED, ""

    def _accept(self, mt: int, items: tuple[Item, ...], sysid: int, compid: int, t: float) -> tuple[int, str]:
        """A whole list arrived (or a clear): the return plan is checked and scheduled; other types are kept."""
        if mt != mav.MAV_MISSION_TYPE_MISSION:
            return ACCEPTED, ""
        try:
            plan = to_plan(items, self.origin)
        except ItemError as e:  # the field named, answered with its MAV_MISSION_INVALID_PARAMn
            return e.fault.result, str(e)
        except ValueError as e:
            return INVALID, str(e)
        error = self.vehicle.set_plan(plan, t)
        if error:
            return UNSUPPORTED, error
        n = len(self.vehicle.status().book.plan) if items else 0
        self.out.statustext(f"return plan: {len(items)} items, {n} leases" if items else "return plan: default")
        return ACCEPTED, ""

    # ----- upload -----------------------------------------------------------------------------------------
    @handles("MISSION_COUNT")
    def _on_count(self, m, src: Source, t: float) -> None:
        self._say(self.transfer.on_count(src.sysid, src.compid, m.count, mission_type(m), t,
                                         self._allowed(src.sysid, src.compid, t)))

    @handles("MISSION_ITEM_INT")
    def _on_item_int(self, m, src: Source, t: float) -> None:
        self._say(self.transfer.on_item(src.sysid, src.compid, item_from_message(m), t))

    @handles("MISSION_ITEM")
    def _on_item(self, m, src: Source, t: float) -> None:
        """The deprecated float item (MAVProxy still sends it): stored in the MISSION_ITEM_INT form."""
        scale = position_scale(m.frame)
        for fld, v in ((5, m.x), (6, m.y)):  # the integer form cannot hold these: refuse them by field
            if not math.isfinite(v) or abs(v * scale) > INT32_MAX:
                self._say(self.transfer.refuse(src.sysid, m.seq, mission_type(m), ItemFault(
                    fld, MISSION_INVALID_PARAM[fld], f"{'xy'[fld - 5]} = {v} is not a position")))
                return
        item = item_from_message(m, round(m.x * scale), round(m.y * scale))
        self._say(self.transfer.on_item(src.sysid, src.compid, item, t))

    @handles("MISSION_CLEAR_ALL")
    def _on_clear_all(self, m, src: Source, t: float) -> None:
        self._say(self.transfer.on_clear(src.sysid, src.compid, mission_type(m), t,
                                         self._allowed(src.sysid, src.compid, t)))

    @handles("MISSION_ACK")
    def _on_ack(self, m, src: Source, t: float) -> None:
        if src.trusted:  # it ends a download for anyone, but only a trusted one may cancel an upload
            self.transfer.on_ack(src.sysid, mission_type(m))

    # ----- download ---------------------------------------------------------------------------------------
    @handles("MISSION_REQUEST_LIST")
    def _on_request_list(self, m, src: Source, t: float) -> None:
        self.transfer.on_request_list(src.sysid, src.compid, mission_type(m))

    @handles("MISSION_REQUEST_INT")
    def _on_request_int(self, m, src: Source, t: float) -> None:
        self.transfer.on_request(src.sysid, src.compid, m.seq, mission_type(m))

    @handles("MISSION_REQUEST")
    def _on_request(self, m, src: Source, t: float) -> None:
        self.transfer.on_request(src.sysid, src.compid, m.seq, mission_type(m), as_int=False)

    # ----- where the plan starts, and how far it got -------------------------------------------------------
    @handles("MISSION_SET_CURRENT")
    def _on_set_current(self, m, src: Source, t: float) -> None:
        error = self.vehicle.set_plan_start(m.seq, src.sysid, src.compid, t)
        if error:
            self.out.statustext(f"set mission current: {error}", mav.MAV_SEVERITY_WARNING)
        self.report(mav.MAVLINK_MSG_ID_MISSION_CURRENT, t)

    @command(mav.MAV_CMD_DO_SET_MISSION_CURRENT)
    def _set_current(self, p: tuple, src: Source, t: float) -> Reply:
        seq = whole(p[0])
        error = self.vehicle.set_plan_start(NO_SEQUENCE if seq is None else seq, src.sysid, src.compid, t)
        if error:
            self.out.statustext(f"set mission current: {error}", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        self.report(mav.MAVLINK_MSG_ID_MISSION_CURRENT, t)
        return mav.MAV_RESULT_ACCEPTED, 0

    def tick(self, t: float) -> None:
        """MISSION_ITEM_REACHED for the plan items reached since the last tick; an upload's time-out."""
        for seq in self.vehicle.drain_reached():
            if seq >= 0:
                self.out.mav.mission_item_reached_send(seq)
        if self.transfer.upload is not None:  # (only an upload in progress has a time-out to run)
            self._say(self.transfer.tick(t))
