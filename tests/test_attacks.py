"""The attack suite (docs/architecture.md §4.1): with a signing key installed, a station without it can watch but never
act.

Each test is one attack from a station that has no key, usually spoofing the owner's sysid (255, compid 190, as
anyone who reads LEASE_STATUS could): it must fail, be counted, and leave the vehicle as it was. The owner signs
with the key throughout, in simulated time (tests/harness.py).
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.plans import parse_spec
from link.signing import Key, SigningVerdict, signature_block, sim_stamp
from tests.harness import Pair
from vehicle.app import State
from vehicle.keystore import KeyStore, read_key, write_key
from vehicle.services.base import mav
from vehicle.services.native import COMMANDS
from vehicle.services.signing import ACCESS, Access

KEY = Key(bytes(range(32)))
OTHER = Key(bytes(range(100, 132)))


def keyed(intruders=(255,), stations=(255,), **options) -> Pair:
    """A keyed vehicle, the owner (255) holding the key and in control, and intruders without it."""
    pair = Pair(stations=stations, vehicle_key=KEY, keys={s: KEY for s in stations}, intruders=intruders, **options)
    pair.take_control()
    assert pair.vehicle.book.owner == 255
    return pair


def refusals(pair: Pair) -> list[str]:
    return [text for _, text in pair.gs.texts if text.startswith(("unsigned", "wrongly signed", "replayed"))]


def test_spoofing_the_owner_cannot_force_a_return():
    pair = keyed()
    intruder = pair.intruders[0]
    p = intruder.rtl()
    intruder.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 5)  # PX4 AUTO_RTL
    pair.step(5.0)
    assert pair.vehicle.state() == State.TELEOP and pair.vehicle.book.owner == 255
    assert not any(e.reason.name == "OPERATOR_EXPIRE" for e in pair.vehicle.event_log)
    assert p.result is None  # dropped, not answered: a refusal ACK would land on the owner's own pending command
    assert pair.endpoint.counters.signing[SigningVerdict.UNSIGNED] >= 2
    assert any(text.startswith("unsigned COMMAND_LONG from 255 refused") for text in refusals(pair))


def test_the_owner_still_acts_while_spoofed():
    pair = keyed()
    pair.intruders[0].drive_velocity(0.0, 0.0)  # a stream of forged stop commands
    r = pair.gs.rtl()
    pair.until(lambda: r.done, 2, "ACK")
    assert r.ok and pair.vehicle.state() in (State.RETURNING, State.HOLDING)


def test_a_replayed_frame_is_refused():
    pair = keyed(intruders=())
    gs = pair.gs
    d = gs.arm(False)
    captured = list(gs.frames)  # the signed DISARM, as a listener on the link would record it
    pair.until(lambda: d.done, 2, "ACK")
    pair.step(3.1)  # an identical ARM within 3 s would be answered, not run (docs/architecture.md §3.9)
    a = gs.arm(True)
    pair.until(lambda: a.done, 2, "ACK")
    pair.step(5.0)  # past the command retry window: only the signature's timestamp tells a replay now
    assert pair.vehicle.armed
    pair.raw.extend(captured)
    pair.step(0.1)
    assert pair.vehicle.armed
    assert pair.endpoint.counters.signing[SigningVerdict.REPLAY] == 1


def test_a_forged_far_future_frame_does_not_lock_the_owner_out():
    pair = keyed(intruders=())
    h = pair.gs.hold()
    forged = bytearray(pair.gs.frames[-1])
    pair.until(lambda: h.done, 2, "ACK")
    block = signature_block(bytes(forged))
    forged[-12:-6] = (block.timestamp + 10**11).to_bytes(6, "little")  # the owner's stream, a year ahead
    pair.raw.append(bytes(forged))
    pair.step(0.1)
    assert pair.endpoint.counters.signing[SigningVerdict.BAD_SIGNATURE] == 1
    r = pair.gs.rtl()
    pair.until(lambda: r.done, 2, "ACK")
    assert r.ok and pair.vehicle.state() in (State.RETURNING, State.HOLDING)


def test_taking_the_root_fails_without_the_key():
    pair = Pair(vehicle_key=KEY, stations=(), intruders=(200,))
    intruder = pair.intruders[0]
    pair.until(lambda: intruder.vehicle.status is not None, 3, "LEASE_STATUS")
    intruder.acquire(allow_takeover=True)
    pair.step(2.0)
    assert pair.vehicle.book.owner is None
    owned = keyed(intruders=(200, 255))
    owned.gs.acquire(allow_takeover=True)  # the owner even allows a takeover
    owned.step(0.5)
    owned.intruders[0].acquire(allow_takeover=True)
    owned.intruders[1].release()  # and a forged release in the owner's name
    owned.step(2.0)
    assert owned.vehicle.book.owner == 255


def test_expiring_the_lease_fails_without_the_key():
    pair = keyed()
    intruder = pair.intruders[0]
    status = intruder.vehicle.status  # the epoch and index, read from the broadcast LEASE_STATUS
    assert status is not None and status.epoch == pair.vehicle.book.epoch
    intruder.expire()
    intruder.command(mav.MAV_CMD_LEASE_CLAIM, status.epoch, status.current + 1)  # nor a newer lease
    pair.step(2.0)
    assert pair.vehicle.state() == State.TELEOP
    assert pair.vehicle.book.current_id.index == status.current


def test_changing_a_parameter_fails_without_the_key():
    pair = keyed()
    intruder = pair.intruders[0]
    intruder.param_set("LNK_TIMEOUT", 120.0)
    intruder.param_set("RTL_REARM", 0.0)
    pair.step(1.0)
    assert pair.vehicle.params["LNK_TIMEOUT"] == 3.0 and pair.vehicle.params["RTL_REARM"] == 1.0
    unowned = Pair(vehicle_key=KEY, stations=(), intruders=(200,))
    unowned.intruders[0].param_set("LNK_TIMEOUT", 120.0)
    unowned.step(1.0)
    assert unowned.vehicle.params["LNK_TIMEOUT"] == 3.0


def test_changing_a_telemetry_rate_fails_without_the_key():
    pair = keyed()
    before = dict(pair.endpoint.telemetry.intervals)
    pair.intruders[0].command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, -1)
    pair.intruders[0].command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_LEASE_STATUS, -1)
    pair.step(1.0)
    assert pair.endpoint.telemetry.intervals == before


def test_uploading_a_plan_fails_without_the_key():
    pair = keyed()
    tr = pair.intruders[0].upload(parse_spec("loiter:5"))
    pair.step(3.0)
    assert pair.vehicle.plan_items == () and not tr.ok
    assert pair.endpoint.missions.upload is None  # not even started
    uploaded = pair.gs.upload(parse_spec("rtl:40 | loiter:10"))
    pair.until(lambda: uploaded.done, 3, "the owner's upload")
    cleared = pair.intruders[0].clear()
    pair.step(2.0)
    assert len(pair.vehicle.plan_items) == 3 and not cleared.ok


def test_a_forged_mission_ack_does_not_cancel_the_owners_upload():
    pair = keyed()
    tr = pair.gs.upload(parse_spec("rtl:40 | loiter:10"))
    pair.intruders[0].mav.mission_ack_send(1, 1, mav.MAV_MISSION_OPERATION_CANCELLED, 0)
    pair.until(lambda: tr.done, 5, "the upload")
    assert tr.ok and pair.endpoint.missions.uploads_cancelled == 0 and len(pair.vehicle.plan_items) == 3


def test_forged_heartbeats_do_not_keep_the_link_alive():
    pair = keyed()
    del pair.stations[255]  # the owner falls silent; the intruder keeps heartbeating in its name
    timeout = pair.vehicle.params["LNK_TIMEOUT"]
    pair.step(timeout + 0.5)
    assert any(e.reason.name == "COMMS_LOST" for e in pair.vehicle.event_log)
    assert pair.endpoint.counters.signing[SigningVerdict.UNSIGNED] >= timeout - 1  # the heartbeats, seen and ignored


def test_a_station_with_another_key_cannot_act():
    pair = Pair(vehicle_key=KEY, keys={255: OTHER})
    p = pair.gs.acquire()
    pair.step(2.0)
    assert pair.vehicle.book.owner is None and p.result is None
    assert pair.endpoint.counters.signing[SigningVerdict.BAD_SIGNATURE] >= 1
    # and it believes none of the vehicle's frames either: they are not signed with its key
    assert pair.gs.vehicle.status is None and pair.gs.refused[SigningVerdict.BAD_SIGNATURE] > 0


def test_an_unsigned_station_can_still_watch():
    pair = keyed()
    intruder = pair.intruders[0]
    intruder.param_request_all()
    down = intruder.download()
    got = []
    intruder.listeners.append(lambda m, t: got.append(m) if m.get_type() == "AUTOPILOT_VERSION" else None)
    q = intruder.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    pair.step(2.0)
    assert intruder.vehicle.status.owner == 255 and intruder.vehicle.position is not None
    assert len(intruder.vehicle.params) == intruder.vehicle.param_count > 0
    assert down.ok and q.ok and got


def test_with_a_key_autogrant_does_nothing():
    pair = Pair(vehicle_key=KEY, keys={255: KEY})
    pair.connect()
    assert pair.vehicle.params["LEASE_AUTOGRANT"] == 1
    r = pair.gs.rtl()
    pair.until(lambda: r.done, 2, "ACK")
    assert r.result == mav.MAV_RESULT_NOT_IN_CONTROL and pair.vehicle.book.owner is None
    p = pair.gs.acquire()
    pair.until(lambda: p.done, 2, "ACK")
    assert p.ok and pair.vehicle.book.owner == 255


def test_refusals_are_announced_at_most_every_two_seconds():
    pair = keyed()
    pair.intruders[0].drive_manual(1.0, 0.0)  # 10 forged teleop frames a second
    pair.step(6.0)
    texts = refusals(pair)
    assert 2 <= len(texts) <= 4
    assert any("more since the last notice" in text for text in texts)
    assert pair.vehicle.setpoint is None


# one unsigned frame of each request a station without the key may make, and what the vehicle answers it with
READ_REQUESTS = {
    "HEARTBEAT": (lambda gs: gs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0), None),
    "PARAM_REQUEST_LIST": (lambda gs: gs.param_request_all(), "PARAM_VALUE"),
    "PARAM_REQUEST_READ": (lambda gs: gs.param_request("LNK_TIMEOUT"), "PARAM_VALUE"),
    "MISSION_REQUEST_LIST": (lambda gs: gs.mav.mission_request_list_send(1, 1, 0), "MISSION_COUNT"),
    "MISSION_REQUEST_INT": (lambda gs: gs.mav.mission_request_int_send(1, 1, 0, 0), "MISSION_ITEM_INT"),
    "MISSION_REQUEST": (lambda gs: gs.mav.mission_request_send(1, 1, 0, 0), "MISSION_ITEM"),
    "MISSION_ACK": (lambda gs: gs.mav.mission_ack_send(1, 1, mav.MAV_MISSION_ACCEPTED, 0), None),
    mav.MAV_CMD_REQUEST_MESSAGE: (
        lambda gs: gs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION), "AUTOPILOT_VERSION"),
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: (
        lambda gs: gs.command(mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1), "AUTOPILOT_VERSION"),
    mav.MAV_CMD_GET_HOME_POSITION: (lambda gs: gs.command(mav.MAV_CMD_GET_HOME_POSITION), "HOME_POSITION"),
}


def _what_a_command_could_change(pair: Pair) -> tuple:
    v, b = pair.vehicle, pair.vehicle.book
    return (b.epoch, b.owner, b.leases, b.plan, b.queue, b.takeover_allowed, v.armed, v.holding, v.setpoint,
            dict(v.params.values), v.plan_items, dict(pair.endpoint.telemetry.intervals))


def test_every_request_the_gate_lets_through_unsigned_is_answered_and_changes_nothing():
    """What the signing gate reads as read-only (ACCESS: READ) an unsigned stranger may ask for: each such
    request passes the gate (not refused there), is answered to the stranger, and leaves everything a
    command could change as it was. A message newly let through must be given a request here."""
    reads = {kind for kind, access in ACCESS.items() if access is Access.READ}
    assert reads <= set(READ_REQUESTS), reads - set(READ_REQUESTS)
    for kind in sorted(reads, key=str):
        pair = Pair(vehicle_key=KEY, keys={255: KEY}, intruders=(245,)).take_control("rtl:30 | loiter:5")
        stranger = pair.intruders[0]
        send, answer = READ_REQUESTS[kind]
        pair.step(0.5)
        before, refused = _what_a_command_could_change(pair), pair.vehicle.commands_rejected
        heard: list[str] = []
        stranger.listeners.append(lambda m, t, heard=heard: heard.append(m.get_type()))
        send(stranger)
        pair.step(0.5)
        assert _what_a_command_could_change(pair) == before, kind
        assert pair.vehicle.commands_rejected == refused, kind  # through the gate, not refused there
        assert answer is None or answer in heard, (kind, sorted(set(heard)))


# ----- SETUP_SIGNING -------------------------------------------------------------------------------------------
def _setup_signing(station, key: Key, timestamp: int) -> None:
    station.mav.setup_signing_send(1, 1, list(key.secret), timestamp)


def test_setup_signing_never_installs_a_first_key():
    pair = Pair()
    pair.connect()
    _setup_signing(pair.gs, KEY, sim_stamp(pair.t))
    pair.step(0.5)
    assert pair.endpoint.key is None
    assert any("signing setup refused: no key installed" in text for _, text in pair.gs.texts)
    assert all(signature_block(f) is None for f in pair.heard)


def test_unsigned_setup_signing_is_refused_and_answered():
    pair = keyed()
    _setup_signing(pair.intruders[0], OTHER, 0)
    pair.step(0.5)
    assert pair.endpoint.key == KEY
    assert any("signing setup from 255 refused: not signed" in text for _, text in pair.gs.texts)


def test_signed_setup_signing_rotates_and_persists_the_key(tmp_path):
    path = tmp_path / "v.key"
    write_key(path, KEY)
    pair = keyed(intruders=(), stations=(255, 250), keystore=KeyStore.open(path))
    old_holder = pair.stations[250]
    pair.gs.rotate_key(OTHER)
    pair.step(0.5)
    assert pair.endpoint.key == OTHER and read_key(path) == OTHER
    assert any("signing key changed by GCS 255" in text for _, text in pair.gs.texts)
    done = pair.gs.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0)  # the owner goes on with the new key
    pair.until(lambda: done.done, 2, "ACK")
    assert done.ok and not pair.vehicle.armed
    old_holder.param_set("LNK_TIMEOUT", 9.0)  # the old key no longer acts
    pair.step(0.5)
    assert pair.vehicle.params["LNK_TIMEOUT"] == 3.0
    assert pair.endpoint.counters.signing[SigningVerdict.BAD_SIGNATURE] >= 1


def test_signing_cannot_be_switched_off_over_the_link():
    pair = keyed(intruders=())
    pair.gs.mav.setup_signing_send(1, 1, [0] * 32, 0)
    pair.step(0.5)
    assert pair.endpoint.key == KEY
    assert any("cannot be switched off" in text for _, text in pair.gs.texts)


def test_a_keyed_station_believes_no_forged_answer():
    pair = keyed(intruders=())
    p = pair.gs.rtl()

    class Sink:
        frames: list[bytes] = []

        def write(self, data: bytes) -> None:
            self.frames.append(bytes(data))

    forger = mav.MAVLink(Sink(), 1, 1)  # the vehicle's ids, without its key
    forger.command_ack_send(mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, mav.MAV_RESULT_DENIED, 0, 0, 255, 190)
    for frame in Sink.frames:
        pair.gs.feed(frame, pair.t)
    assert not p.done and pair.gs.refused[SigningVerdict.UNSIGNED] == 1
    pair.until(lambda: p.done, 2, "the vehicle's own ACK")
    assert p.ok


def test_a_setup_signing_timestamp_beyond_48_bits_is_refused():
    pair = keyed(intruders=())
    pair.gs.mav.setup_signing_send(1, 1, list(OTHER.secret), 2**48)
    pair.step(0.5)
    assert pair.endpoint.key == KEY
    assert any("initial timestamp outside 48 bits" in text for _, text in pair.gs.texts)


COMMAND_IDS = sorted(COMMANDS)


@settings(max_examples=15, deadline=None)
@given(st.sampled_from(COMMAND_IDS), st.lists(st.floats(-1e3, 1e5, allow_nan=False), min_size=7, max_size=7),
       st.sampled_from(["long", "int"]))
def test_property_no_command_from_a_station_without_the_key_changes_anything(command, p, kind):
    pair = keyed()
    v, intruder = pair.vehicle, pair.intruders[0]
    before = (v.book, v.armed, v.holding, dict(v.params.values), v.plan_items,
              dict(pair.endpoint.telemetry.intervals))
    if kind == "long":
        intruder.mav.command_long_send(1, 1, command, 0, *p)
    else:
        intruder.mav.command_int_send(1, 1, 0, command, 0, 0, *p[:4], int(p[4]), int(p[5]), p[6])
    pair.step(0.1)
    after = (v.book, v.armed, v.holding, dict(v.params.values), v.plan_items,
             dict(pair.endpoint.telemetry.intervals))
    assert after[1:] == before[1:]
    assert (after[0].epoch, after[0].owner, after[0].current_id) == (before[0].epoch, before[0].owner,
                                                                     before[0].current_id)
