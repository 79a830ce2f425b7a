"""MAVLink 2 signing, one behaviour per test (docs/architecture.md §4.1): the pure verifier, key and timestamp files,
and the vehicle's signing clock across a reboot."""

from __future__ import annotations

import os
import stat

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from link import dialect
from link.signing import (
    NEW_STREAM_WINDOW,
    Key,
    KeyFileError,
    SigningVerdict,
    Streams,
    enable,
    load_key,
    parse_key,
    sign_frame,
    signature_block,
    sim_stamp,
    stamp_from_unix,
    timestamp_of,
)
from link.storage import StoredFileError
from tests.harness import Pair
from vehicle.keystore import KeyStore, boot_stamp, read_key, stamp_path, write_key

mav = dialect.load()
KEY = Key(bytes(range(32)))
OTHER = Key(bytes(range(1, 33)))
NOW = sim_stamp(1000.0)


class _Frames:
    def __init__(self) -> None:
        self.out: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.out.append(bytes(data))


def signed_heartbeat(key: Key, timestamp: int, sysid: int = 255, compid: int = 190, link_id: int = 0) -> bytes:
    """A heartbeat signed by pymavlink itself, so the verifier is checked against another implementation."""
    sink = _Frames()
    m = mav.MAVLink(sink, sysid, compid)
    enable(m, key, timestamp, link_id)
    m.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE)
    return sink.out[0]


def unsigned_heartbeat(sysid: int = 255) -> bytes:
    sink = _Frames()
    mav.MAVLink(sink, sysid, 190).heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    return sink.out[0]


def forged(timestamp: int, sysid: int = 255, compid: int = 190, link_id: int = 0) -> bytes:
    """A frame that claims to be signed (flag set, well-formed block) without knowing the key."""
    genuine = signed_heartbeat(OTHER, timestamp, sysid, compid, link_id)
    return genuine[:-6] + b"\x00" * 6


# ----- the verifier --------------------------------------------------------------------------------------------
def test_a_frame_signed_with_the_key_is_accepted_and_starts_its_stream():
    frame = signed_heartbeat(KEY, NOW)
    streams, verdict = Streams().verify(KEY, frame, NOW)
    assert verdict is SigningVerdict.ACCEPT
    assert streams.last == {(255, 190, 0): NOW}


def test_our_signature_is_the_one_pymavlink_computes():
    frame = signed_heartbeat(KEY, NOW, link_id=7)
    assert sign_frame(KEY, frame[:-13], 7, NOW) == frame
    assert signature_block(frame).stream == (255, 190, 7)


def test_unsigned_and_wrong_key_frames_are_named():
    assert Streams().verify(KEY, unsigned_heartbeat(), NOW)[1] is SigningVerdict.UNSIGNED
    assert Streams().verify(KEY, signed_heartbeat(OTHER, NOW), NOW)[1] is SigningVerdict.BAD_SIGNATURE


def test_a_forged_frame_never_moves_a_streams_timestamp():
    streams, _ = Streams().verify(KEY, signed_heartbeat(KEY, NOW), NOW)
    far_future = NOW + 10**12
    after, verdict = streams.verify(KEY, forged(far_future), NOW)
    assert verdict is SigningVerdict.BAD_SIGNATURE
    assert after == streams  # untouched: the owner's next genuine frame still gets in
    assert after.verify(KEY, signed_heartbeat(KEY, NOW + 1), NOW)[1] is SigningVerdict.ACCEPT


def test_a_forged_frame_never_opens_a_stream():
    after, verdict = Streams().verify(KEY, forged(NOW + 10**12, sysid=42), NOW)
    assert verdict is SigningVerdict.BAD_SIGNATURE and after.last == {}


def test_a_replayed_frame_is_refused():
    frame = signed_heartbeat(KEY, NOW)
    streams, _ = Streams().verify(KEY, frame, NOW)
    assert streams.verify(KEY, frame, NOW)[1] is SigningVerdict.REPLAY
    assert streams.verify(KEY, signed_heartbeat(KEY, NOW - 1), NOW)[1] is SigningVerdict.REPLAY


def test_streams_are_per_sysid_compid_and_link_id():
    streams, _ = Streams().verify(KEY, signed_heartbeat(KEY, NOW), NOW)
    for other in (dict(sysid=254), dict(compid=191), dict(link_id=1)):
        assert streams.verify(KEY, signed_heartbeat(KEY, NOW, **other), NOW)[1] is SigningVerdict.ACCEPT


def test_a_new_stream_may_be_at_most_60_s_behind_our_clock():
    assert NEW_STREAM_WINDOW == 60 * 100_000
    assert Streams().verify(KEY, signed_heartbeat(KEY, NOW - NEW_STREAM_WINDOW), NOW)[1] is SigningVerdict.ACCEPT
    assert Streams().verify(KEY, signed_heartbeat(KEY, NOW - NEW_STREAM_WINDOW - 1), NOW)[1] is SigningVerdict.TOO_OLD


def test_the_60_s_rule_is_for_new_streams_only():
    old = NOW - 10 * NEW_STREAM_WINDOW
    streams, _ = Streams().verify(KEY, signed_heartbeat(KEY, old), old)
    assert streams.verify(KEY, signed_heartbeat(KEY, old + 1), NOW)[1] is SigningVerdict.ACCEPT


def test_signing_timestamps_count_10_us_since_2015():
    assert stamp_from_unix(1420070400.0) == 0
    assert stamp_from_unix(1420070401.5) == 150_000


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["genuine", "forged", "replay"]), st.integers(-10**7, 10**9),
                          st.integers(0, 2)), max_size=30))
def test_property_accepted_timestamps_only_grow_and_forgeries_change_nothing(steps):
    streams, sent, newest = Streams(), [], {}
    for kind, offset, sysid in steps:
        if kind == "replay" and sent:
            frame = sent[offset % len(sent)]
        elif kind == "forged":
            frame = forged(NOW + offset, sysid=200 + sysid)
        else:
            frame = signed_heartbeat(KEY, NOW + offset, sysid=200 + sysid)
            sent.append(frame)
        stream = signature_block(frame).stream
        after, verdict = streams.verify(KEY, frame, NOW)
        if kind == "forged":
            assert verdict is SigningVerdict.BAD_SIGNATURE and after == streams
        if verdict is SigningVerdict.ACCEPT:
            assert timestamp_of(frame) > newest.get(stream, -1)
            newest[stream] = timestamp_of(frame)
        else:
            assert after == streams
        if kind == "genuine" and stream in newest and timestamp_of(frame) > newest[stream]:
            pytest.fail("a genuine newer frame was locked out")
        streams = after
    assert streams.last == newest


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_property_no_altered_frame_is_accepted(data):
    frame = bytearray(signed_heartbeat(KEY, NOW))
    position = data.draw(st.integers(0, len(frame) - 1))
    frame[position] ^= data.draw(st.integers(1, 255))
    assert Streams().verify(KEY, bytes(frame), NOW)[1] is not SigningVerdict.ACCEPT


# ----- key files -----------------------------------------------------------------------------------------------
def test_a_key_file_is_one_line_of_64_hex_characters(tmp_path):
    path = tmp_path / "v.key"
    write_key(path, KEY)
    assert path.read_text() == KEY.hex() + "\n"
    assert read_key(path) == KEY == load_key(path)


def test_a_new_key_file_is_private_and_never_overwritten(tmp_path):
    path = tmp_path / "v.key"
    write_key(path, KEY)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    with pytest.raises(FileExistsError):
        write_key(path, OTHER)
    assert read_key(path) == KEY
    write_key(path, OTHER, force=True)
    assert read_key(path) == OTHER


@pytest.mark.parametrize("text, line, what", [
    ("", 1, "empty"),
    ("abcd\n", 1, "4 characters"),
    ("zz" * 32 + "\n", 1, "not hexadecimal"),
    (KEY.hex() + "\n\nextra\n", 3, "after the key"),
])
def test_a_damaged_key_file_is_named_with_its_line(tmp_path, text, line, what):
    path = tmp_path / "v.key"
    path.write_text(text)
    with pytest.raises(StoredFileError) as e:
        read_key(path)
    assert (e.value.path, e.value.line) == (str(path), line) and what in str(e.value)
    with pytest.raises(KeyFileError) as g:  # the ground station's loader says the same
        load_key(path)
    assert str(g.value) == str(e.value)


def test_a_missing_key_file_is_named(tmp_path):
    with pytest.raises(StoredFileError) as e:
        KeyStore.open(tmp_path / "none.key")
    assert str(tmp_path / "none.key") in str(e.value)


def test_a_key_never_shows_its_secret():
    assert KEY.hex() not in repr(KEY) and KEY.fingerprint in repr(KEY)


def test_a_passphrase_key_is_the_one_mavproxy_derives():
    import hashlib

    assert Key.from_passphrase("tunnel-7").secret == hashlib.sha256(b"tunnel-7").digest()
    assert parse_key(Key.from_passphrase("tunnel-7").hex()) == Key.from_passphrase("tunnel-7")


# ----- the vehicle's signing timestamp -------------------------------------------------------------------------
def test_boot_continues_after_the_saved_timestamp_or_the_clock():
    assert boot_stamp(None, 500) == 500
    assert boot_stamp(900, 500) == 901  # the clock went backwards (no RTC): continue after the saved one
    assert boot_stamp(100, 500) == 500


def test_the_timestamp_is_saved_every_minute_and_at_shutdown(tmp_path):
    path = tmp_path / "v.key"
    write_key(path, KEY)
    pair = Pair(keystore=KeyStore.open(path))
    pair.step(29.0)
    assert not stamp_path(path).exists()
    pair.step(2.0)
    first = int(stamp_path(path).read_text())
    pair.step(5.0)
    pair.endpoint.close()
    last = int(stamp_path(path).read_text())
    assert last > first and last >= max(timestamp_of(f) for f in pair.heard)


def test_timestamps_never_go_backwards_across_a_reboot_with_a_clock_behind(tmp_path):
    path = tmp_path / "v.key"
    write_key(path, KEY)
    first = Pair(keystore=KeyStore.open(path))
    first.step(10.0)
    first.endpoint.close()
    used = max(timestamp_of(f) for f in first.heard)
    # the second boot's clock reads 1 h earlier than the first boot's did
    second = Pair(keystore=KeyStore.open(path), stamp=lambda t: sim_stamp(t) - 3600 * 100_000)
    second.step(1.0)
    assert min(timestamp_of(f) for f in second.heard) > used


def test_a_damaged_timestamp_file_is_named_and_refused(tmp_path):
    path = tmp_path / "v.key"
    write_key(path, KEY)
    stamp_path(path).write_text("12x\n")
    with pytest.raises(StoredFileError) as e:
        KeyStore.open(path)
    assert e.value.path == str(stamp_path(path)) and e.value.line == 1


def test_every_frame_the_keyed_vehicle_sends_is_signed():
    pair = Pair(vehicle_key=KEY)
    pair.step(3.0)
    assert pair.heard and all(signature_block(f) is not None for f in pair.heard)
    streams = Streams()
    for f in pair.heard:
        streams, verdict = streams.verify(KEY, f, sim_stamp(pair.t))
        assert verdict is SigningVerdict.ACCEPT
