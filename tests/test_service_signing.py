"""The signing service alone: the gate's verdicts, key rotation over a signed link only, the timestamp file."""

from __future__ import annotations

from link.signing import Key, sim_stamp
from tests.service_kit import OWNER, STRANGER, Kit, texts
from vehicle.keystore import STAMP_SAVE_EVERY, KeyStore, write_key
from vehicle.services.base import mav
from vehicle.services.signing import REJECT_NOTICE_GAP, Signing

KEY = Key(bytes(range(1, 33)))
NEW = Key(bytes(range(101, 133)))


def keyed(kit: Kit, **options) -> Signing:
    return Signing(kit.out, kit.vehicle, 0.0, key=KEY, **options)


def framed(kit: Kit, msg, sysid: int = OWNER, key: Key | None = None):
    """``msg`` as station ``sysid`` sends it (signed with ``key`` if given), parsed as the endpoint parses it."""
    return kit.parse(kit.frame(msg, sysid, key=key))


def param_set(value: float = 5.0):
    return mav.MAVLink_param_set_message(1, 1, b"LNK_TIMEOUT", value, mav.MAV_PARAM_TYPE_REAL32)


def setup_signing(secret: bytes, initial: int = 0):
    return mav.MAVLink_setup_signing_message(1, 1, secret, initial)


def test_a_frame_signed_with_the_key_is_trusted():
    kit = Kit()
    gate = keyed(kit)
    assert gate.check(framed(kit, param_set(), key=KEY), OWNER, 0.0) is True
    assert kit.replies() == []


def test_an_unsigned_read_passes_untrusted_and_an_unsigned_act_is_dropped_and_told():
    kit = Kit()
    gate = keyed(kit)
    read = mav.MAVLink_param_request_list_message(1, 1)
    assert gate.check(framed(kit, read, STRANGER), STRANGER, 0.0) is False  # answered, never "the owner heard"
    assert gate.check(framed(kit, param_set(), STRANGER), STRANGER, 0.0) is None
    told = texts(kit.replies())
    assert len(told) == 1 and "PARAM_SET from 66 refused" in told[0]
    assert kit.vehicle.commands_rejected == 1


def test_refusals_are_told_at_most_every_gap_with_the_count_in_between():
    kit = Kit()
    gate = keyed(kit)
    told = []
    for k in range(int(2 * REJECT_NOTICE_GAP / 0.1) + 1):  # 10 Hz of forged writes for two gaps
        gate.check(framed(kit, param_set(), STRANGER), STRANGER, k * 0.1)
        told += texts(kit.replies())
    assert len(told) == 3
    assert told[1].endswith(f"(+{int(REJECT_NOTICE_GAP / 0.1) - 1} more since the last notice)")


def test_without_a_key_setup_signing_is_refused_and_nothing_is_installed():
    kit = Kit()
    gate = Signing(kit.out, kit.vehicle, 0.0)
    told = texts(kit.send(gate, setup_signing(NEW.secret)))
    assert gate.key is None
    assert told and "no key installed" in told[0]


def test_rotation_needs_a_frame_signed_with_the_installed_key():
    kit = Kit()
    gate = keyed(kit)
    told = texts(kit.send(gate, setup_signing(NEW.secret), trusted=False))
    assert gate.key == KEY and "not signed with the installed key" in told[0]
    told = texts(kit.send(gate, setup_signing(bytes(32)), trusted=True))
    assert gate.key == KEY and "cannot be switched off" in told[0]
    told = texts(kit.send(gate, setup_signing(NEW.secret, sim_stamp(1.0)), trusted=True))
    assert gate.key == NEW and f"key id {NEW.fingerprint}" in told[0]


def test_rotation_goes_to_the_key_file_and_the_timestamp_is_saved_every_period(tmp_path):
    path = tmp_path / "vehicle.key"
    write_key(path, KEY)
    store = KeyStore.open(path)
    kit = Kit()
    gate = Signing(kit.out, kit.vehicle, 0.0, keystore=store)
    kit.send(gate, setup_signing(NEW.secret), trusted=True)
    assert KeyStore.open(path).key == NEW
    saved = store.saved_stamp
    gate.tick(STAMP_SAVE_EVERY / 2)
    assert store.saved_stamp == saved  # not yet
    gate.tick(STAMP_SAVE_EVERY + 1.0)
    assert store.saved_stamp is not None and store.saved_stamp > (saved or 0)
    assert KeyStore.open(path).saved_stamp == store.saved_stamp
