"""The vehicle's own actions as commands (docs/architecture.md §4): arm, modes, return to launch, return to link.

Every action is a state change under the lease rules: the vehicle decides (``Vehicle.command``, ``rtl``,
``take_manual``) and this service answers with what it decided. A mode arrives in the PX4 or the
ArduPilot Rover numbering (DO_SET_MODE, the SET_MODE message) or as a standard mode (DO_SET_STANDARD_MODE);
each means one of three things here: RTL (the operator lease expires), HOLD or MANUAL. A companion computer routes
these to its autopilot instead of composing this service.
"""

from __future__ import annotations

from link.modes import px4_parts
from link.plan_items import NAV_RETURN_TO_LINK
from vehicle.modes import decode_mode
from vehicle.port import CommandAuthority
from vehicle.service import PlanItem
from vehicle.services.base import Outbox, Reply, Service, Source, command, handles, mav
from vehicle.services.commands import answer

# DO_SET_STANDARD_MODE -> what it means on this vehicle (a mission is the return plan)
STANDARD_MODES = {mav.MAV_STANDARD_MODE_SAFE_RECOVERY: "RTL", mav.MAV_STANDARD_MODE_POSITION_HOLD: "HOLD",
                  mav.MAV_STANDARD_MODE_MISSION: "RTL"}
ARMED = 0.5  # COMPONENT_ARM_DISARM p1 at or above: arm


class VehicleActions(Service):
    """Arm, modes and returns, each judged by the lease rules."""

    def __init__(self, out: Outbox, vehicle: CommandAuthority) -> None:
        self.out = out
        self.vehicle = vehicle

    @command(mav.MAV_CMD_COMPONENT_ARM_DISARM)
    def _arm(self, p: tuple, src: Source, t: float) -> Reply:
        arm = p[0] >= ARMED
        chk = self.vehicle.command(src.sysid, src.compid, t, ("arm", arm))
        return answer(self.out, chk, "arm" if arm else "disarm", src.sysid)

    @command(mav.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    def _rtl(self, p: tuple, src: Source, t: float) -> Reply:
        return answer(self.out, self.vehicle.rtl(src.sysid, src.compid, t), "return", src.sysid)

    @command(mav.MAV_CMD_NAV_RETURN_TO_LINK)
    def _return_to_link(self, p: tuple, src: Source, t: float) -> Reply:
        """RETURN_TO_LINK as a command: run this one return block now, keep the stored plan."""
        # the command service already checked the parameters against link.plan_items.KINDS and filled NaN with
        # "use the parameter" values (command_values), exactly as an uploaded item is
        item = PlanItem(NAV_RETURN_TO_LINK, *p[:5])
        chk = self.vehicle.rtl(src.sysid, src.compid, t, (item,))
        return answer(self.out, chk, "return to link", src.sysid)

    @command(mav.MAV_CMD_DO_SET_MODE)
    def _set_mode(self, p: tuple, src: Source, t: float) -> Reply:
        return self.mode(decode_mode(int(p[0]), int(p[1]), int(p[2])), src, t)

    @command(mav.MAV_CMD_DO_SET_STANDARD_MODE)
    def _set_standard_mode(self, p: tuple, src: Source, t: float) -> Reply:
        return self.mode(STANDARD_MODES.get(int(p[0])), src, t)

    @handles("SET_MODE")
    def _on_set_mode(self, m, src: Source, t: float) -> None:
        """The deprecated SET_MODE message: no answer but the mode itself (and a STATUSTEXT when refused)."""
        custom = int(m.custom_mode)
        if custom > 0xFFFF:  # the PX4 encoding: main and sub mode in the upper bytes
            main, sub = px4_parts(custom)
            mode = decode_mode(m.base_mode, main, sub)
        else:
            mode = decode_mode(m.base_mode, custom, 0)
        self.mode(mode, src, t)

    def mode(self, mode: str | None, src: Source, t: float) -> Reply:
        """RTL, HOLD or MANUAL (None: a mode this vehicle does not have)."""
        if mode is None:
            self.out.statustext("mode not supported", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        if mode == "RTL":
            return self._rtl((), src, t)
        v = self.vehicle
        chk = v.take_manual(src.sysid, src.compid, t)
        if chk.executes and mode == "HOLD":
            v.command(src.sysid, src.compid, t, ("hold",))
        return answer(self.out, chk, f"mode {mode}", src.sysid)
