"""The range of every parameter of the commands the vehicle honours, checked before a command is executed.

A COMMAND_LONG or COMMAND_INT carries seven floats; a NaN where a boolean is expected reads as "false" and an
out-of-range enum reaches the code that uses it. Each command's parameters are checked here first, so a bad one is
answered DENIED with a STATUSTEXT naming the parameter and never half-executed. RETURN_TO_LINK as a command uses
the same fields as the plan item (``link.plan_items.KINDS``). Commands not listed take no parameters that matter.
"""

from __future__ import annotations

from link import dialect
from link.plan_items import KINDS, NAV_RETURN_TO_LINK, UNUSED, FieldRange

mav = dialect.load()

MSG_ID = FieldRange("message id", 0, 2**24 - 1, integer=True)
OPTIONAL_SWITCH = FieldRange("0 or 1", 0, 1, integer=True, nan=0.0)


def _params(*fields: FieldRange) -> tuple[FieldRange, ...]:
    return (*fields, *(UNUSED,) * (7 - len(fields)))


COMMAND_PARAMS: dict[int, tuple[FieldRange, ...]] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: _params(FieldRange("arm", 0, 1, integer=True)),  # p2 force: ignored
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: _params(),
    mav.MAV_CMD_NAV_RETURN_TO_LINK: KINDS[NAV_RETURN_TO_LINK].fields,
    mav.MAV_CMD_DO_SET_MODE: _params(FieldRange("base mode", 0, 255, integer=True),
                                     FieldRange("custom mode", 0, 255, integer=True),
                                     FieldRange("custom sub mode", 0, 255, integer=True, nan=0.0)),
    mav.MAV_CMD_DO_SET_STANDARD_MODE: _params(FieldRange("standard mode", 0, 255, integer=True)),
    mav.MAV_CMD_REQUEST_MESSAGE: _params(MSG_ID),  # p2..p7 belong to the requested message
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: _params(),
    mav.MAV_CMD_GET_HOME_POSITION: _params(),
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: _params(MSG_ID, FieldRange("interval", -1, 1e9)),  # us; -1 off, 0 default
    mav.MAV_CMD_REQUEST_OPERATOR_CONTROL: _params(
        FieldRange("request", 0, 1, integer=True), OPTIONAL_SWITCH, FieldRange("timeout", 0, 3600, nan=0.0),
        FieldRange("requester sysid", 0, 255, integer=True, nan=0.0)),
    mav.MAV_CMD_LEASE_CLAIM: _params(FieldRange("epoch", 0, 65535, integer=True),
                                     FieldRange("index", -1, 65534, integer=True)),
    mav.MAV_CMD_LEASE_EXPIRE: _params(FieldRange("epoch", 0, 65535, integer=True),
                                      FieldRange("index", 0, 65534, integer=True)),
    mav.MAV_CMD_DO_SET_MISSION_CURRENT: _params(FieldRange("sequence", -1, 65535, integer=True),
                                                FieldRange("reset", 0, 1, integer=True, nan=0.0)),
}


def command_name(command: int) -> str:
    entry = mav.enums["MAV_CMD"].get(command)
    return entry.name if entry is not None else f"command {command}"


def check_command(command: int, params: tuple[float, ...]) -> str | None:
    """Why this command's parameters are refused (naming the parameter), or None."""
    fields = COMMAND_PARAMS.get(command)
    if fields is None:
        return None
    for i, (f, v) in enumerate(zip(fields, params, strict=True), 1):
        why = f.check(float(v))
        if why is not None:
            return f"{command_name(command)} param{i} ({f.label}): {why}"
    return None


def command_values(command: int, params: tuple[float, ...]) -> tuple[float, ...]:
    """The checked parameters with NaN replaced by what it stands for."""
    fields = COMMAND_PARAMS.get(command)
    if fields is None:
        return tuple(params)
    return tuple(f.value(v) if f.used else v for f, v in zip(fields, params, strict=True))
