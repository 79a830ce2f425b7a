"""Return plans on the ground: QGC WPL 110 files and a short text form (``rtl:50 | loiter:30 | launch``).

A plan is a list of ``link.mission.Item`` in the MISSION_ITEM_INT form, exactly what goes over the wire.
Every item is checked against the same field ranges the vehicle applies (``link.plan_items``), so a plan the
vehicle would refuse is refused here, before it is uploaded, with the file and line or the spec word named.
"""

from __future__ import annotations

import math

from link.mission import Item, Origin
from link.plan_items import (
    LEASE_BOUNDARY,
    LOCAL_FRAMES,
    MISSION_FRAME,
    NAMES,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_RETURN_TO_LINK,
    NAV_WAYPOINT,
    check_item,
    position_scale,
)

WPL_HEADER = "QGC WPL 110"
LOCAL_NED = LOCAL_FRAMES[0]  # MAV_FRAME_LOCAL_NED: the frame of a waypoint given in metres north and east


class PlanError(ValueError):
    pass


def _checked(it: Item, where: str) -> Item:
    """The item, or PlanError naming where it came from and the field the vehicle would refuse."""
    fault = check_item(it.command, it.frame, (it.param1, it.param2, it.param3, it.param4), it.x, it.y, it.z,
                       it.current, it.autocontinue)
    if fault is not None:
        raise PlanError(f"{where}: {fault.message}")
    return it


def item(seq: int, command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0, p4: float = 0.0,
         frame: int = MISSION_FRAME, x: int = 0, y: int = 0) -> Item:
    return Item(seq, frame, command, 0, 1, p1, p2, p3, p4, x, y, 0.0, 0)


def parse_spec(text: str, origin: Origin | None = None) -> list[Item]:
    """``rtl[:disp[:speed[:target[:on_regain]]]] | loiter:seconds | launch | wp:north:east``, blocks separated
    by ``|``. Raises PlanError naming the word and the field out of range."""
    items: list[Item] = []
    for k, block in enumerate(text.split("|")):
        if k:
            items.append(item(len(items), LEASE_BOUNDARY))
        for word in block.split():
            name, *args = word.split(":")
            try:
                nums = [float(a) for a in args]
            except ValueError:
                raise PlanError(f"{word!r}: arguments must be numbers") from None
            if name == "rtl" and len(nums) <= 4:
                p = nums + [0.0, 0.0, -1.0, -1.0][len(nums):]
                new = item(len(items), NAV_RETURN_TO_LINK, p[0], p[1], p[2], p[3])
            elif name == "loiter" and len(nums) == 1:
                new = item(len(items), NAV_LOITER_TIME, nums[0])
            elif name == "launch" and not nums:
                new = item(len(items), NAV_RETURN_TO_LAUNCH)
            elif name == "wp" and len(nums) == 2 and all(math.isfinite(v) and abs(v) < 1e6 for v in nums):
                scale = position_scale(LOCAL_NED)
                new = item(len(items), NAV_WAYPOINT, frame=LOCAL_NED, x=round(nums[0] * scale),
                           y=round(nums[1] * scale))
            else:
                raise PlanError(f"{word!r}: expected rtl[:disp[:speed[:target[:on_regain]]]], loiter:S, launch "
                                f"or wp:N:E")
            items.append(_checked(new, repr(word)))
    if not items:
        raise PlanError("empty plan")
    return items


def read_wpl(text: str, source: str = "<plan>") -> list[Item]:
    """QGC WPL 110: a header line, then ``seq current frame command p1 p2 p3 p4 x y z autocontinue``."""
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines or not lines[0].startswith("QGC WPL"):
        raise PlanError(f"{source}:1: not a QGC WPL file (expected '{WPL_HEADER}')")
    items = []
    for n, line in enumerate(lines[1:], 2):
        f = line.replace(",", " ").split()
        if len(f) != 12:
            raise PlanError(f"{source}:{n}: expected 12 fields, got {len(f)}")
        try:
            seq, cur, frame, cmd = (int(v) for v in f[:4])
            p1, p2, p3, p4, x, y, z = (float(v) for v in f[4:11])
            auto = int(f[11])
        except ValueError as e:
            raise PlanError(f"{source}:{n}: {e}") from None
        if seq != len(items):
            raise PlanError(f"{source}:{n}: item {seq} out of sequence (expected {len(items)})")
        scale = position_scale(frame)
        if not (math.isfinite(x) and math.isfinite(y) and abs(x * scale) < 2**31 and abs(y * scale) < 2**31):
            raise PlanError(f"{source}:{n}: position is not a number in range")
        items.append(_checked(Item(seq, frame, cmd, cur, auto, p1, p2, p3, p4, round(x * scale), round(y * scale),
                                   z, 0), f"{source}:{n}"))
    return items


def write_wpl(items: list[Item]) -> str:
    out = [WPL_HEADER]
    for it in items:
        scale = position_scale(it.frame)
        out.append("\t".join(str(v) for v in (
            it.seq, it.current, it.frame, it.command, f"{it.param1:g}", f"{it.param2:g}", f"{it.param3:g}",
            f"{it.param4:g}", f"{it.x / scale:.8f}", f"{it.y / scale:.8f}", f"{it.z:g}", it.autocontinue)))
    return "\n".join(out) + "\n"


def describe(items: list[Item]) -> str:
    lines = []
    lease = 0
    for it in items:
        if it.command == LEASE_BOUNDARY:
            lease += 1
            lines.append(f"{it.seq:3d}  ---- lease boundary ----")
            continue
        name = NAMES.get(it.command, f"CMD {it.command}")
        detail = {NAV_RETURN_TO_LINK: f"max disp {it.param1:g} m, speed {it.param2:g} m/s, target {it.param3:g}",
                  NAV_LOITER_TIME: f"{it.param1:g} s"}.get(it.command, "")
        lines.append(f"{it.seq:3d}  block {lease}  {name:<17} {detail}")
    return "\n".join(lines)


def from_plan_items(plan) -> list[Item]:
    """Local ``vehicle.service.PlanItem``s (a scenario's plan) -> mission items to upload."""
    out = []
    for k, p in enumerate(plan):
        if p.command == NAV_WAYPOINT:
            scale = position_scale(LOCAL_NED)
            out.append(item(k, p.command, p.param1, p.param2, p.param3, p.param4, frame=LOCAL_NED,
                            x=round(p.x * scale), y=round(p.y * scale)))
        else:
            out.append(item(k, p.command, p.param1, p.param2, p.param3, p.param4))
    return out
