"""The companion's router alone (docs/architecture.md §11): where a ground frame goes, the authority it needs, the
decision against a lease book, and the answer a refused frame gets. Messages and lease books only: no companion, no
socket."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from link import dialect
from vehicle.companion.router import Action, Authority, Dest, answers, decide, lease_text, route, what
from vehicle.lease import LeaseBook

rl = dialect.load()
enc = apm.MAVLink(None, 255, 190)


def cmd(command: int, comp: int = 1, system: int = 1, *params: float):
    p = list(params) + [0.0] * (7 - len(params))
    return enc.command_long_encode(system, comp, command, 0, *p)


def ftp(opcode: int, comp: int = 1):
    payload = [0] * 251
    payload[3] = opcode
    return enc.file_transfer_protocol_encode(0, 1, comp, payload)


@pytest.mark.parametrize("msg, dest, access", [
    (cmd(rl.MAV_CMD_LEASE_CLAIM, 191), Dest.COMPANION, Authority.READ),
    (cmd(rl.MAV_CMD_REQUEST_OPERATOR_CONTROL, 0), Dest.COMPANION, Authority.READ),
    (cmd(rl.MAV_CMD_NAV_RETURN_TO_LINK, 0, 0), Dest.COMPANION, Authority.READ),
    (cmd(apm.MAV_CMD_DO_SET_MODE, 191), Dest.COMPANION, Authority.READ),  # addressed to 191: native semantics
    (cmd(apm.MAV_CMD_COMPONENT_ARM_DISARM, 191), Dest.MISDIRECTED, Authority.READ),  # only the autopilot arms
    (enc.set_position_target_local_ned_encode(0, 1, 191, 8, 0x05C7, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0),
     Dest.MISDIRECTED, Authority.READ),
    (cmd(apm.MAV_CMD_DO_SET_MODE, 1), Dest.AUTOPILOT, Authority.MODE),
    (cmd(apm.MAV_CMD_DO_SET_MODE, 0), Dest.AUTOPILOT, Authority.MODE),  # a broadcast mode change is the autopilot's
    (cmd(apm.MAV_CMD_NAV_RETURN_TO_LAUNCH, 1), Dest.AUTOPILOT, Authority.MODE),
    (cmd(apm.MAV_CMD_COMPONENT_ARM_DISARM, 1), Dest.AUTOPILOT, Authority.LEASE),
    (cmd(apm.MAV_CMD_REQUEST_MESSAGE, 1), Dest.AUTOPILOT, Authority.READ),
    (cmd(apm.MAV_CMD_SET_MESSAGE_INTERVAL, 1), Dest.AUTOPILOT, Authority.OWNER),
    (enc.set_mode_encode(1, 1, 4), Dest.AUTOPILOT, Authority.MODE),
    (enc.param_request_list_encode(1, 0), Dest.AUTOPILOT, Authority.READ),
    (enc.param_request_list_encode(1, 191), Dest.COMPANION, Authority.READ),
    (enc.param_set_encode(1, 1, b"FS_ACTION", 2, 2), Dest.AUTOPILOT, Authority.OWNER),
    (enc.request_data_stream_encode(1, 1, 0, 4, 1), Dest.AUTOPILOT, Authority.OWNER),
    (enc.mission_count_encode(1, 0, 3, 0), Dest.AUTOPILOT, Authority.PLAN),
    (enc.mission_request_list_encode(1, 0, 0), Dest.AUTOPILOT, Authority.READ),
    (enc.mission_count_encode(1, 191, 3, 0), Dest.COMPANION, Authority.READ),  # the return plan
    (enc.manual_control_encode(1, 500, 0, 500, 0, 0), Dest.AUTOPILOT, Authority.LEASE),
    (enc.rc_channels_override_encode(1, 1, *([1500] * 8)), Dest.AUTOPILOT, Authority.LEASE),
    (enc.set_position_target_local_ned_encode(0, 1, 1, 8, 0x05C7, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0),
     Dest.AUTOPILOT, Authority.LEASE),
    (ftp(4), Dest.AUTOPILOT, Authority.READ),  # OpenFileRO: MAVProxy fetches parameters this way
    (ftp(7), Dest.AUTOPILOT, Authority.PLAN),  # WriteFile
    (enc.heartbeat_encode(6, 8, 0, 0, 4), Dest.KEEP, Authority.READ),
    (enc.setup_signing_encode(1, 1, [1] * 32, 0), Dest.SIGNING, Authority.READ),
    (cmd(apm.MAV_CMD_DO_SET_MODE, 1, 2), Dest.ELSEWHERE, Authority.READ),  # another vehicle
    (cmd(apm.MAV_CMD_DO_SET_MODE, 100), Dest.ELSEWHERE, Authority.READ),  # a camera on this one
    (enc.manual_control_encode(2, 500, 0, 500, 0, 0), Dest.ELSEWHERE, Authority.READ),
])
def test_route(msg, dest, access):
    r = route(msg, 1)
    assert (r.dest, r.authority) == (dest, access)


def unowned() -> LeaseBook:
    return LeaseBook()


def owned_by(owner: int = 255) -> LeaseBook:
    return LeaseBook().acquire(owner, 190, 0.0).book


def returning(owner: int = 255) -> LeaseBook:
    book = owned_by(owner)
    out, _ = book.expire_current(owner, 1.0)
    assert out.book.returning
    return out.book


@pytest.mark.parametrize("access, kind", [
    (Authority.READ, Action.FORWARD), (Authority.OWNER, Action.FORWARD), (Authority.PLAN, Action.ADMIT),
    (Authority.LEASE, Action.ADMIT), (Authority.MODE, Action.TAKE),
])
def test_an_unowned_vehicle_grants_plain_clients_as_the_native_one_does(access, kind):
    assert decide(access, 255, 190, unowned(), 0.0).kind is kind


def test_with_a_key_nobody_is_granted_the_root_by_a_command():
    d = decide(Authority.LEASE, 255, 190, unowned(), 0.0, keyed=True)
    assert d.kind is Action.REFUSE and d.result == rl.MAV_RESULT_NOT_IN_CONTROL


def test_an_unsigned_state_change_is_refused_without_an_acknowledgement():
    d = decide(Authority.LEASE, 255, 190, owned_by(255), 0.0, trusted=False, keyed=True)
    assert d.kind is Action.REFUSE and d.result is None
    assert decide(Authority.READ, 255, 190, owned_by(255), 0.0, trusted=False, keyed=True).kind is Action.FORWARD


@pytest.mark.parametrize("access", [Authority.OWNER, Authority.PLAN, Authority.LEASE])
def test_a_stranger_is_refused_not_in_control_naming_the_lease(access):
    d = decide(access, 254, 190, owned_by(255), 0.0)
    assert d.kind is Action.REFUSE and d.result == rl.MAV_RESULT_NOT_IN_CONTROL
    assert "GCS 255" in d.why and "[" in d.why


def test_the_owner_under_its_claimed_lease_is_forwarded():
    book = owned_by(255)
    for access in (Authority.OWNER, Authority.PLAN, Authority.LEASE):
        assert decide(access, 255, 190, book, 0.0).kind is Action.FORWARD


def test_during_a_return_the_owners_stale_commands_are_refused_as_expired():
    d = decide(Authority.LEASE, 255, 190, returning(255), 2.0)
    assert d.kind is Action.REFUSE and d.result == rl.MAV_RESULT_DENIED
    assert "expired" in d.why and "the return holds lease" in d.why
    assert decide(Authority.MODE, 255, 190, returning(255), 2.0).kind is Action.TAKE  # a mode change takes it back


def test_during_a_return_a_stranger_cannot_take_over():
    d = decide(Authority.LEASE, 254, 190, returning(255), 2.0)
    assert d.kind is Action.REFUSE and "return in progress" in d.why


def test_lease_text():
    assert lease_text(unowned()) == "nobody owns the vehicle"
    assert "(claimed) of GCS 255" in lease_text(owned_by(255))


def test_answers_are_what_the_autopilot_would_send():
    ack = answers(cmd(apm.MAV_CMD_COMPONENT_ARM_DISARM, 1), 254, 190, rl.MAV_RESULT_NOT_IN_CONTROL)
    (comp, m), = ack.to_ground
    assert comp == 1 and m.get_type() == "COMMAND_ACK"
    assert (m.command, m.result, m.target_system, m.target_component) == (400, rl.MAV_RESULT_NOT_IN_CONTROL, 254, 190)
    (_, m), = answers(enc.set_mode_encode(1, 1, 4), 254, 190, apm.MAV_RESULT_DENIED).to_ground
    assert m.command == apm.MAVLINK_MSG_ID_SET_MODE  # ArduPilot acknowledges SET_MODE by its message id
    (_, m), = answers(enc.mission_count_encode(1, 0, 3, 2), 254, 190, apm.MAV_RESULT_DENIED).to_ground
    assert m.get_type() == "MISSION_ACK" and m.type == apm.MAV_MISSION_DENIED and m.mission_type == 2
    a = answers(enc.param_set_encode(1, 1, b"FS_ACTION", 0, 2), 254, 190, apm.MAV_RESULT_DENIED)
    assert not a.to_ground and [str(x.param_id) for x in a.to_autopilot] == ["FS_ACTION"]
    (_, m), = answers(ftp(7), 254, 190, apm.MAV_RESULT_DENIED).to_ground
    assert bytes(m.payload)[3] == 129 and bytes(m.payload)[5] == 7  # NAK of WriteFile
    streams = answers(enc.manual_control_encode(1, 500, 0, 500, 0, 0), 254, 190, apm.MAV_RESULT_DENIED)
    assert streams == ([], [])  # a stream's answer is the rate-limited STATUSTEXT
    assert answers(cmd(400, 1), 255, 190, None) == ([], [])  # unsigned: no acknowledgement at all


def test_what_names_commands():
    assert what(cmd(rl.MAV_CMD_LEASE_CLAIM, 191)) == "LEASE_CLAIM"
    assert what(cmd(apm.MAV_CMD_DO_SET_MODE)) == "DO_SET_MODE"
    assert what(enc.manual_control_encode(1, 0, 0, 0, 0, 0)) == "MANUAL_CONTROL"
