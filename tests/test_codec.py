"""link/codec.py: ``read_frames`` answers exactly as pymavlink's ``parse_buffer`` would, datagram after datagram, for
clean frames, signed frames, frames back to back, fragments, garbage, bad checksums and unknown flags: the same
messages (type, bytes, sequence number, signature), the same parser counters, the same exceptions."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.generator.mavcrc import x25crc

from link import dialect
from link.codec import read_frames
from link.signing import Key, enable

mav = dialect.load()


class _Sink:
    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.frames.append(bytes(data))


def _frames() -> list[bytes]:
    """A few real frames: small and large, unsigned and signed, several senders."""
    out: list[bytes] = []
    for sysid, signed in ((255, False), (42, True)):
        sink = _Sink()
        enc = mav.MAVLink(sink, sysid, 190)
        if signed:
            enable(enc, Key(bytes(range(1, 33))), 10_000)
        enc.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE)
        enc.command_long_send(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        enc.set_position_target_local_ned_send(0, 1, 1, 1, 0b110111000111, 0, 0, 0, 1.0, 0.5, 0, 0, 0, 0, 0, 0.2)
        enc.statustext_send(mav.MAV_SEVERITY_INFO, b"x" * 50)
        out += sink.frames
    return out


FRAMES = _frames()


def _parser():
    p = mav.MAVLink(None, 0, 0)
    p.robust_parsing = True
    return p


def _mutate(frame: bytes, how: int, where: int, value: int) -> bytes:
    b = bytearray(frame)
    i = where % len(b)
    if how == 0:
        return bytes(b)  # intact
    if how == 1:
        b[i] = value  # a flipped byte: bad checksum, bad length, bad flags, bad marker...
        return bytes(b)
    if how == 2:
        return bytes(b[:i])  # a fragment
    if how == 3:
        return bytes([value]) * (i + 1)  # garbage
    return bytes(b) + bytes(b[:i])  # a frame and the start of another


_datagram = st.lists(
    st.tuples(st.integers(0, len(FRAMES) - 1), st.integers(0, 4), st.integers(0, 400), st.integers(0, 255)),
    min_size=1, max_size=3).map(lambda parts: b"".join(_mutate(FRAMES[k], h, w, v) for k, h, w, v in parts))


def _answer(parser, read, data):
    try:
        msgs = read(parser, data)
    except Exception as e:  # noqa: BLE001 - the exception itself is part of the answer
        return ("raised", type(e).__name__)
    return [(m.get_type(), bytes(m.get_msgbuf()), m.get_seq(), m.get_srcSystem(), getattr(m, "reason", None))
            for m in msgs]


def _counters(p) -> tuple:
    return (p.total_bytes_received, p.total_packets_received, p.total_receive_errors, p.buf_len(),
            p.expected_length, p.have_prefix_error)


@settings(max_examples=400, deadline=None)
@given(st.lists(_datagram, min_size=1, max_size=8))
def test_read_frames_answers_as_parse_buffer_does(datagrams):
    ours, theirs = _parser(), _parser()
    for data in datagrams:
        got = _answer(ours, read_frames, data)
        want = _answer(theirs, lambda p, d: p.parse_buffer(d) or [], data)
        assert got == want
        assert _counters(ours) == _counters(theirs)


def test_one_clean_frame_per_datagram_is_decoded_once_with_its_sequence_and_signature():
    p = _parser()
    for frame in FRAMES:
        (m,) = read_frames(p, frame)
        assert m.get_type() != "BAD_DATA"
        assert bytes(m.get_msgbuf()) == frame
        assert m.get_seq() == frame[4]
    # the signed frames kept their signature block (the endpoint's signing check reads it from the message)
    assert any(frame[2] & 1 for frame in FRAMES)
    assert p.total_packets_received == len(FRAMES) and p.total_receive_errors == 0


def test_a_frame_with_a_bad_checksum_is_bad_data_and_counted():
    p = _parser()
    bad = bytearray(FRAMES[0])
    bad[-1] ^= 0xFF
    (m,) = read_frames(p, bytes(bad))
    assert m.get_type() == "BAD_DATA"
    assert p.total_receive_errors == 1
    (m,) = read_frames(p, FRAMES[1])  # and the next frame is read as usual
    assert m.get_type() == "COMMAND_LONG"


def test_two_frames_in_one_datagram_are_both_read():
    msgs = read_frames(_parser(), FRAMES[0] + FRAMES[1])
    assert [m.get_type() for m in msgs] == ["HEARTBEAT", "COMMAND_LONG"]


def test_a_well_checksummed_frame_with_unknown_flags_is_bad_data():
    """Incompatibility flags this parser does not know mean it cannot read the frame, whatever its checksum."""
    b = bytearray(FRAMES[0])
    b[2] = 0x02
    crc = x25crc(bytes(b[1:-2]))
    crc.accumulate(bytes([mav.mavlink_map[b[7] | b[8] << 8 | b[9] << 16].crc_extra]))
    b[-2:] = crc.crc.to_bytes(2, "little")
    p, q = _parser(), _parser()
    assert _answer(p, read_frames, bytes(b)) == _answer(q, lambda p, d: p.parse_buffer(d) or [], bytes(b))
    assert read_frames(_parser(), bytes(b))[0].get_type() == "BAD_DATA"
