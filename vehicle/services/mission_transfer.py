"""The vehicle side of the MAVLink mission transfer, for mission types 0 (the return plan), 1 (fence) and 2 (rally).

Uploads are transactions: the vehicle requests every item with MISSION_REQUEST_INT, re-requests on a timeout, and
only when the last item has arrived and the whole list is accepted does it replace the stored list. A cancelled,
timed-out or refused upload leaves the previous plan exactly as it was. Errors are MISSION_ACK codes. What the
lists mean (a return plan to schedule) is the mission service's business (``vehicle.services.mission``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from link import dialect
from link.mission import Item, Origin
from link.plan_items import (
    GLOBAL_FRAMES,
    MAX_DISPLACEMENT,
    MISSION_INVALID_PARAM,
    NAV_WAYPOINT,
    ItemError,
    ItemFault,
    check_item,
    position_scale,
    values,
)
from vehicle.service import PlanItem

ITEM_TIMEOUT = 0.5  # s before an item is requested again
ITEM_RETRIES = 5
MAX_ITEMS = 500

mav = dialect.load()

# MAV_MISSION_RESULT, as the transfer answers
ACCEPTED, UNSUPPORTED, NO_SPACE, INVALID = (mav.MAV_MISSION_ACCEPTED, mav.MAV_MISSION_UNSUPPORTED,
                                            mav.MAV_MISSION_NO_SPACE, mav.MAV_MISSION_INVALID)
INVALID_SEQUENCE, DENIED, OPERATION_CANCELLED = (mav.MAV_MISSION_INVALID_SEQUENCE, mav.MAV_MISSION_DENIED,
                                                 mav.MAV_MISSION_OPERATION_CANCELLED)
MISSION_TYPES = (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_FENCE, mav.MAV_MISSION_TYPE_RALLY)


def to_plan(items: tuple[Item, ...], origin: Origin) -> tuple[PlanItem, ...]:
    """Mission items -> return-plan items in the local frame.

    Every field is checked against ``link.plan_items.KINDS`` first: raises ``ItemError`` naming the item, the
    field and the MAV_MISSION_RESULT to answer with, so an unusable plan is refused at upload, never at return.
    """
    out = []
    for it in items:
        fault = check_item(it.command, it.frame, (it.param1, it.param2, it.param3, it.param4), it.x, it.y, it.z,
                           it.current, it.autocontinue)
        if fault is not None:
            raise ItemError(it.seq, fault)
        scale = position_scale(it.frame)
        p = values(it.command, it.frame, (it.param1, it.param2, it.param3, it.param4, it.x / scale, it.y / scale,
                                          it.z))
        x, y = p[4], p[5]
        if it.command == NAV_WAYPOINT and it.frame in GLOBAL_FRAMES:
            x, y = origin.to_local(x, y)
            if math.hypot(x, y) > MAX_DISPLACEMENT:
                raise ItemError(it.seq, ItemFault(5, MISSION_INVALID_PARAM[5],
                                                  f"WAYPOINT at {math.hypot(x, y):.0f} m from the origin: "
                                                  f"at most {MAX_DISPLACEMENT:g} m"))
        out.append(PlanItem(it.command, p[0], p[1], p[2], p[3], x, y, it.seq))
    return tuple(out)


@dataclass
class _Upload:
    sysid: int
    compid: int
    mission_type: int
    count: int
    items: list[Item]
    asked_at: float
    retries: int = 0


class MissionServer:
    """One vehicle's stored lists and the transfer in progress.

    ``send(name, **fields)`` emits a message; ``accept(mission_type, items, sysid, compid, t)`` returns a
    MAV_MISSION_RESULT and a reason, and is where the return plan is validated and scheduled.
    """

    def __init__(self, send: Callable[..., None],
                 accept: Callable[[int, tuple[Item, ...], int, int, float], tuple[int, str]]) -> None:
        self.send = send
        self.accept = accept
        self.lists: dict[int, tuple[Item, ...]] = {mt: () for mt in MISSION_TYPES}
        self.upload: _Upload | None = None
        self.uploads_cancelled = 0

    def _ack(self, sysid: int, compid: int, result: int, mission_type: int) -> None:
        self.send("mission_ack", target_system=sysid, target_component=compid, type=result,
                  mission_type=mission_type)

    def _request(self, up: _Upload, t: float) -> None:
        up.asked_at = t
        self.send("mission_request_int", target_system=up.sysid, target_component=up.compid,
                  seq=len(up.items), mission_type=up.mission_type)

    # ----- upload ------------------------------------------------------------------------------------------
    def on_count(self, sysid: int, compid: int, count: int, mission_type: int, t: float,
                 allowed: tuple[int, str]) -> str | None:
        """MISSION_COUNT starts an upload (and aborts any other). ``allowed`` is the lease verdict."""
        if mission_type not in self.lists:
            self._ack(sysid, compid, UNSUPPORTED, mission_type)
            return f"mission type {mission_type} not supported"
        if allowed[0] != ACCEPTED:
            self._ack(sysid, compid, allowed[0], mission_type)
            return allowed[1]
        if count > MAX_ITEMS:
            self._ack(sysid, compid, NO_SPACE, mission_type)
            return f"{count} items: at most {MAX_ITEMS}"
        self.upload = None
        if count == 0:
            return self._finish(_Upload(sysid, compid, mission_type, 0, [], t), t)
        self.upload = _Upload(sysid, compid, mission_type, count, [], t)
        self._request(self.upload, t)
        return None

    def on_item(self, sysid: int, compid: int, item: Item, t: float) -> str | None:
        up = self.upload
        if up is None or sysid != up.sysid or item.mission_type != up.mission_type:
            return None  # not ours: a stray or duplicate item after the transfer ended
        expected = len(up.items)
        if item.seq < expected:
            return None  # a duplicate of an item we already have (our re-request crossed it)
        if item.seq > expected:
            self._request(up, t)  # out of order: ask again for the one we need
            return None
        if up.mission_type == mav.MAV_MISSION_TYPE_MISSION:
            # a return-plan item is checked as it arrives: the ACK names the bad field
            fault = check_item(item.command, item.frame, (item.param1, item.param2, item.param3, item.param4),
                               item.x, item.y, item.z, item.current, item.autocontinue)
            if fault is not None:
                return self.refuse(sysid, item.seq, item.mission_type, fault)
        up.items.append(item)
        up.retries = 0
        if len(up.items) == up.count:
            self.upload = None
            return self._finish(up, t)
        self._request(up, t)
        return None

    def refuse(self, sysid: int, seq: int, mission_type: int, fault: ItemFault) -> str | None:
        """End the upload in progress from ``sysid`` at item ``seq`` with the fault's MISSION_ACK; the stored
        list stays as it was. Returns the reason for a STATUSTEXT (None when there was no such upload)."""
        up = self.upload
        if up is None or up.sysid != sysid or up.mission_type != mission_type or seq != len(up.items):
            return None
        self.upload = None
        self._ack(up.sysid, up.compid, fault.result, up.mission_type)
        return f"mission item {seq} refused: {fault.message}; previous plan kept"

    def _finish(self, up: _Upload, t: float) -> str | None:
        items = tuple(up.items)
        result, why = self.accept(up.mission_type, items, up.sysid, up.compid, t)
        if result == ACCEPTED:
            self.lists[up.mission_type] = items
        self._ack(up.sysid, up.compid, result, up.mission_type)
        return None if result == ACCEPTED else why

    def on_ack(self, sysid: int, mission_type: int) -> None:
        """A ground station cancels its upload by sending MISSION_ACK with an error."""
        if self.upload is not None and self.upload.sysid == sysid and self.upload.mission_type == mission_type:
            self.upload = None
            self.uploads_cancelled += 1

    def tick(self, t: float) -> str | None:
        up = self.upload
        if up is None or t - up.asked_at < ITEM_TIMEOUT:
            return None
        if up.retries >= ITEM_RETRIES:
            self.upload = None
            self.uploads_cancelled += 1
            self._ack(up.sysid, up.compid, OPERATION_CANCELLED, up.mission_type)
            return f"mission upload timed out at item {len(up.items)}; previous plan kept"
        up.retries += 1
        self._request(up, t)
        return None

    # ----- download ----------------------------------------------------------------------------------------
    def on_request_list(self, sysid: int, compid: int, mission_type: int) -> None:
        if mission_type not in self.lists:
            self._ack(sysid, compid, UNSUPPORTED, mission_type)
            return
        self.send("mission_count", target_system=sysid, target_component=compid,
                  count=len(self.lists[mission_type]), mission_type=mission_type)

    def on_request(self, sysid: int, compid: int, seq: int, mission_type: int, as_int: bool = True) -> None:
        items = self.lists.get(mission_type)
        if items is None:
            self._ack(sysid, compid, UNSUPPORTED, mission_type)
            return
        if not 0 <= seq < len(items):
            self._ack(sysid, compid, INVALID_SEQUENCE, mission_type)
            return
        it = items[seq]
        fields = dict(target_system=sysid, target_component=compid, seq=seq, frame=it.frame, command=it.command,
                      current=it.current, autocontinue=it.autocontinue, param1=it.param1, param2=it.param2,
                      param3=it.param3, param4=it.param4, z=it.z, mission_type=mission_type)
        if as_int:
            self.send("mission_item_int", x=it.x, y=it.y, **fields)
        else:
            scale = position_scale(it.frame)
            self.send("mission_item", x=it.x / scale, y=it.y / scale, **fields)

    def on_clear(self, sysid: int, compid: int, mission_type: int, t: float, allowed: tuple[int, str]) -> str | None:
        if mission_type == mav.MAV_MISSION_TYPE_ALL:
            types = list(self.lists)
        elif mission_type in self.lists:
            types = [mission_type]
        else:
            self._ack(sysid, compid, UNSUPPORTED, mission_type)
            return f"mission type {mission_type} not supported"
        if allowed[0] != ACCEPTED:
            self._ack(sysid, compid, allowed[0], mission_type)
            return allowed[1]
        for mt in types:
            result, why = self.accept(mt, (), sysid, compid, t)
            if result != ACCEPTED:
                self._ack(sysid, compid, result, mission_type)
                return why
            self.lists[mt] = ()
        self._ack(sysid, compid, ACCEPTED, mission_type)
        return None
