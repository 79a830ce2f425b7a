"""Routing with authority between the ground side and the autopilot (docs/architecture.md §11), as pure functions.

A companion sits on the only wire between the operator's radio and the autopilot, so it can do what the native
vehicle does in its own code: every state change must come from the owner under the current execution lease. It
cannot change the autopilot, so it decides per frame, the way mavlink-router decides per frame where to send it:

* ``route`` says where a ground frame goes (the companion's own endpoint, the autopilot, nowhere) and how much
  authority it needs there (``Authority``), from the message alone;
* ``decide`` weighs that against the lease book (an immutable value) and answers FORWARD, REFUSE, or ask the
  vehicle first (ADMIT: a plain client may be granted the root; TAKE: a mode change takes the operator lease
  back), the same three paths the native endpoint takes through ``Vehicle.admit`` and ``Vehicle.take_manual``;
* ``answers`` builds what a refused frame gets back, in the autopilot's name, so an unmodified client sees its
  command answered (COMMAND_ACK, MISSION_ACK, its parameter re-read, an FTP NAK) instead of timing out.

The authority levels copy the native endpoint's, not a stricter rule: reads from anyone; parameter writes and
telemetry rates from the owner or from anyone while nobody owns the vehicle (ground stations set rates as they
connect, and that must not make them the owner); mission uploads may grant a plain client the root; commands,
setpoints and manual control need the current lease; mode changes go through ``take_manual``.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

from pymavlink.dialects.v20 import ardupilotmega as apm

from link import dialect, ftp
from vehicle.lease import LeaseBook, RejectReason, Verdict

rl = dialect.load()

COMPANION_COMPID = apm.MAV_COMP_ID_ONBOARD_COMPUTER  # 191: the companion's own component id (docs/architecture.md §11)
AUTOPILOT_COMPID = apm.MAV_COMP_ID_AUTOPILOT1

# returnlink's own commands: the autopilot knows none of them, so broadcast ones go to the companion
OWN_COMMANDS = frozenset((rl.MAV_CMD_REQUEST_OPERATOR_CONTROL, rl.MAV_CMD_LEASE_CLAIM, rl.MAV_CMD_LEASE_EXPIRE,
                          rl.MAV_CMD_NAV_RETURN_TO_LINK))

# the answer to a refusal, by reason, as the native vehicle gives it (vehicle/services/commands.py REJECT_RESULT)
REJECT_RESULT = {
    RejectReason.NOT_IN_CONTROL: rl.MAV_RESULT_NOT_IN_CONTROL,
    RejectReason.WRONG_EPOCH: rl.MAV_RESULT_DENIED,
    RejectReason.EXPIRED: rl.MAV_RESULT_DENIED,
    RejectReason.INVALID: rl.MAV_RESULT_DENIED,
}



class Dest(enum.Enum):
    """Where a ground frame goes."""

    COMPANION = "companion"  # the companion's own endpoint: addressed to component 191, or returnlink's commands
    MISDIRECTED = "misdirected"  # addressed to 191 but the autopilot's business (arming, setpoints): refused
    AUTOPILOT = "autopilot"  # the autopilot, if the sender may send it
    KEEP = "keep"  # the companion hears it, the autopilot never does (heartbeats: the keepalive is the backstop)
    SIGNING = "signing"  # SETUP_SIGNING: neither (a key is changed by restarting with --key)
    ELSEWHERE = "elsewhere"  # addressed to another system or component: dropped


class Authority(enum.Enum):
    """How much authority a frame for the autopilot needs (the native endpoint's levels)."""

    READ = "read"  # parameter and mission download, single-message requests, time sync: anyone
    OWNER = "owner"  # parameter writes, telemetry rates, correction streams: the owner, or anyone while unowned
    PLAN = "plan"  # mission, fence and rally uploads, file writes: the owner; may grant a plain client the root
    LEASE = "lease"  # commands, setpoints, manual control, RC override: the owner under the current lease
    MODE = "mode"  # mode changes: the owner takes the operator lease (``Vehicle.take_manual``)


class Routing(NamedTuple):
    dest: Dest
    authority: Authority = Authority.READ


READ_MESSAGES = frozenset((
    "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_EXT_REQUEST_LIST", "PARAM_EXT_REQUEST_READ",
    "MISSION_REQUEST_LIST", "MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_REQUEST_PARTIAL_LIST", "MISSION_ACK",
    "TIMESYNC", "SYSTEM_TIME", "PING", "LOG_REQUEST_LIST", "LOG_REQUEST_DATA", "LOG_REQUEST_END",
    "AUTOPILOT_VERSION_REQUEST", "FENCE_FETCH_POINT", "RALLY_FETCH_POINT", "TERRAIN_DATA", "TERRAIN_CHECK",
    "REMOTE_LOG_BLOCK_STATUS",
))
OWNER_MESSAGES = frozenset(("PARAM_SET", "PARAM_EXT_SET", "REQUEST_DATA_STREAM", "GPS_RTCM_DATA",
                            "GPS_INJECT_DATA"))
PLAN_MESSAGES = frozenset(("MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_CLEAR_ALL",
                           "MISSION_WRITE_PARTIAL_LIST", "MISSION_SET_CURRENT", "FENCE_POINT", "RALLY_POINT"))
KEEP_MESSAGES = frozenset(("HEARTBEAT", "RADIO_STATUS", "RADIO"))
READ_COMMANDS = frozenset((apm.MAV_CMD_REQUEST_MESSAGE, apm.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
                           apm.MAV_CMD_GET_HOME_POSITION, apm.MAV_CMD_REQUEST_PROTOCOL_VERSION,
                           apm.MAV_CMD_REQUEST_FLIGHT_INFORMATION, apm.MAV_CMD_GET_MESSAGE_INTERVAL,
                           apm.MAV_CMD_REQUEST_STORAGE_INFORMATION, apm.MAV_CMD_REQUEST_CAMERA_INFORMATION))
OWNER_COMMANDS = frozenset((apm.MAV_CMD_SET_MESSAGE_INTERVAL,))
MODE_COMMANDS = frozenset((apm.MAV_CMD_DO_SET_MODE, apm.MAV_CMD_NAV_RETURN_TO_LAUNCH, apm.MAV_CMD_MISSION_START,
                           apm.MAV_CMD_DO_SET_STANDARD_MODE))
COMMANDS = ("COMMAND_LONG", "COMMAND_INT")
# what moves the robot itself: the companion's endpoint would take it for its own robot, which here is the autopilot
# and is armed and driven only by the autopilot (sent to component 191 it would be accepted and do nothing)
ROBOT_MESSAGES = frozenset(("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT", "RC_CHANNELS_OVERRIDE",
                            "SET_ATTITUDE_TARGET"))
ROBOT_COMMANDS = frozenset((apm.MAV_CMD_COMPONENT_ARM_DISARM,))


def route(m, sysid: int) -> Routing:
    """Where the ground frame ``m`` goes and the authority it needs, for the vehicle whose autopilot is ``sysid``.

    To the companion: what is addressed to component 191, and returnlink's own commands sent to every component
    (the autopilot would only answer UNSUPPORTED). To the autopilot: everything else addressed to this system or
    to all. Standard messages sent to every component go to the autopilot alone: a broadcast mode change or
    mission upload is the autopilot's business, and two answers to one request confuse ground stations."""
    kind = m.get_type()
    if kind in KEEP_MESSAGES:
        return Routing(Dest.KEEP)
    if kind == "SETUP_SIGNING":
        return Routing(Dest.SIGNING)
    target_system = _field(m, "target_system", "target")
    if target_system not in (None, 0, sysid):
        return Routing(Dest.ELSEWHERE)
    target_component = _field(m, "target_component")
    command = m.command if kind in COMMANDS else None
    if target_component == COMPANION_COMPID:
        return Routing(Dest.MISDIRECTED if kind in ROBOT_MESSAGES or command in ROBOT_COMMANDS else Dest.COMPANION)
    if command in OWN_COMMANDS and target_component in (None, 0):
        return Routing(Dest.COMPANION)
    if target_component not in (None, 0, AUTOPILOT_COMPID):
        return Routing(Dest.ELSEWHERE)  # a camera, a gimbal, another companion: not on this wire's far side
    return Routing(Dest.AUTOPILOT, authority(m))


def authority(m) -> Authority:
    """The authority a frame for the autopilot needs; anything not listed changes state under the lease."""
    kind = m.get_type()
    if kind in COMMANDS:
        c = m.command
        if c in READ_COMMANDS:
            return Authority.READ
        if c in OWNER_COMMANDS:
            return Authority.OWNER
        return Authority.MODE if c in MODE_COMMANDS else Authority.LEASE
    if kind in READ_MESSAGES:
        return Authority.READ
    if kind in OWNER_MESSAGES:
        return Authority.OWNER
    if kind in PLAN_MESSAGES:
        return Authority.PLAN
    if kind == "SET_MODE":
        return Authority.MODE
    if kind == "FILE_TRANSFER_PROTOCOL":
        payload = bytes(m.payload)
        return Authority.READ if len(payload) > 3 and payload[3] in ftp.READS else Authority.PLAN
    return Authority.LEASE


def _field(m, *names: str) -> int | None:
    fields = m.get_fieldnames() if hasattr(m, "get_fieldnames") else ()
    for name in names:
        if name in fields:
            return int(getattr(m, name))
    return None


# ----- decisions -----------------------------------------------------------------------------------------------
class Action(enum.Enum):
    FORWARD = "forward"  # to the autopilot
    REFUSE = "refuse"  # answered (``result``, None: not acknowledged) and announced (``why``)
    ADMIT = "admit"  # grant the sender the root first (LEASE_AUTOGRANT), then decide again
    TAKE = "take"  # the sender takes the operator lease (``Vehicle.take_manual``); forward if that executes


class Decision(NamedTuple):
    kind: Action
    result: int | None = None  # MAV_RESULT of the COMMAND_ACK a refused command gets (None: no acknowledgement)
    why: str = ""


FORWARD = Decision(Action.FORWARD)


def decide(access_: Authority, sender: int, scomp: int, book: LeaseBook, t: float, *, trusted: bool = True,
           keyed: bool = False) -> Decision:
    """What to do with a frame for the autopilot from ``sender`` needing ``access_``, under ``book``.

    ``keyed``: a signing key is installed, and ``trusted``: this frame is signed with it (docs/architecture.md
    §4.1): then an unsigned state change is refused without an acknowledgement (a forged frame with the owner's sysid
    must not make the companion answer the owner's own pending command) and no plain client is ever granted the root."""
    if access_ is Authority.READ:
        return FORWARD
    if keyed and not trusted:
        return Decision(Action.REFUSE, None, "not signed with the vehicle's key")
    owner = book.owner
    if access_ is Authority.MODE:
        return Decision(Action.TAKE)
    grantable = not keyed and sender != owner and book.admit(sender, scomp, t).book.owner == sender
    if access_ is Authority.OWNER:
        return FORWARD if owner is None or owner == sender else _not_owner(book)
    if access_ is Authority.PLAN:
        if grantable:
            return Decision(Action.ADMIT)
        return FORWARD if owner is None or owner == sender else _not_owner(book)
    chk = book.check(sender)
    if chk.verdict is Verdict.EXECUTE:
        return FORWARD
    if grantable:
        return Decision(Action.ADMIT)
    if chk.verdict is Verdict.QUEUE:  # the autopilot has no queue: a command for a later lease is not sent
        return Decision(Action.REFUSE, rl.MAV_RESULT_TEMPORARILY_REJECTED,
                        f"{chk.lease} is scheduled, not current; {lease_text(book)}")
    reason = chk.reason or RejectReason.INVALID
    return Decision(Action.REFUSE, REJECT_RESULT[reason], f"{chk.detail or reason.value}; {lease_text(book)}")


def _not_owner(book: LeaseBook) -> Decision:
    return Decision(Action.REFUSE, rl.MAV_RESULT_NOT_IN_CONTROL, f"GCS {book.owner} is in control; {lease_text(book)}")


def lease_text(book: LeaseBook | None) -> str:
    """The current execution lease in words, for the STATUSTEXT that names why a frame was refused."""
    if book is None or book.owner is None or book.epoch is None or book.current is None:
        return "nobody owns the vehicle"
    cur = book.current
    if book.returning:
        return f"the return holds lease [{book.epoch},{cur.index}] of GCS {book.owner}"
    state = "claimed" if cur.claimed else "unclaimed"
    return f"current lease [{book.epoch},{cur.index}] ({state}) of GCS {book.owner}"


# ----- answers -------------------------------------------------------------------------------------------------
class Answers(NamedTuple):
    to_ground: list  # (source component, message): sent in the autopilot's name
    to_autopilot: list  # messages the companion sends the autopilot on the refused sender's behalf


def answers(m, sender: int, scomp: int, result: int | None) -> Answers:
    """What the refused ground frame ``m`` gets back, as the native vehicle (and the autopilot) would answer it:
    COMMAND_ACK for a command (``result``; SET_MODE is acknowledged as ArduPilot does, with its message id),
    MISSION_ACK DENIED for an upload, the unchanged value for a parameter write (the autopilot is asked to send
    it again), an FTP NAK for a file write. Streams (setpoints, manual control) get nothing: their STATUSTEXT is
    the answer, rate-limited by the caller."""
    kind = m.get_type()
    comp = _field(m, "target_component") or AUTOPILOT_COMPID
    ground: list = []
    autopilot: list = []
    if kind in COMMANDS and result is not None:
        ground.append((comp, apm.MAVLink_command_ack_message(m.command, result, 0, 0, sender, scomp)))
    elif kind == "SET_MODE" and result is not None:
        ground.append((comp, apm.MAVLink_command_ack_message(apm.MAVLINK_MSG_ID_SET_MODE, result, 0, 0, sender,
                                                             scomp)))
    elif kind in PLAN_MESSAGES and kind not in ("FENCE_POINT", "RALLY_POINT", "MISSION_SET_CURRENT") \
            and result is not None:
        ground.append((comp, apm.MAVLink_mission_ack_message(sender, scomp, apm.MAV_MISSION_DENIED,
                                                             getattr(m, "mission_type", 0))))
    elif kind == "PARAM_SET" and result is not None:
        autopilot.append(apm.MAVLink_param_request_read_message(m.target_system, m.target_component,
                                                                _param_id(m.param_id), -1))
    elif kind == "FILE_TRANSFER_PROTOCOL" and result is not None:
        p = ftp.decode(m.payload)
        if p is not None and p.opcode < ftp.OP_ACK:
            nak = ftp.encode(p.seq + 1, p.session, ftp.OP_NAK, bytes((ftp.ERR_FILE_PROTECTED,)), 0, p.opcode)
            ground.append((comp, apm.MAVLink_file_transfer_protocol_message(0, sender, scomp, nak)))
    return Answers(ground, autopilot)


def what(m) -> str:
    """A frame named for a person: the command's name for a command, else the message type."""
    kind = m.get_type()
    if kind in COMMANDS:
        entry = rl.enums["MAV_CMD"].get(m.command) or apm.enums["MAV_CMD"].get(m.command)
        return entry.name.removeprefix("MAV_CMD_") if entry is not None else f"command {m.command}"
    return kind


def _param_id(raw) -> bytes:
    if isinstance(raw, str):
        raw = raw.encode("ascii", "replace")
    return bytes(raw).split(b"\x00", 1)[0]
