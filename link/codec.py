"""Reading MAVLink frames out of datagrams, with pymavlink's own parser, at the cost of one frame per datagram.

Both ends (``vehicle.endpoint.Endpoint`` and ``gcs.station.GroundStation``) receive UDP datagrams or radio packets,
and almost every one holds exactly one complete MAVLink 2 frame. pymavlink's ``parse_buffer`` does not know that:
it runs its byte-stream state machine over the datagram, then calls it again to learn that nothing is left, and at
50 Hz both ends pay that for every frame. ``read_frames`` gives the same answer cheaper:

* a datagram that is exactly one well-formed MAVLink 2 frame, with nothing left over in the parser from earlier
  bytes, goes straight to the parser's own ``decode`` (checksum, CRC extra, signature block, sequence number: the
  very code ``parse_buffer`` ends in), with the parser's counters kept as ``parse_char`` keeps them;
* anything else (several frames, a fragment, garbage, MAVLink 1, unknown flags, a parser holding a partial frame,
  a parser without ``robust_parsing``) takes pymavlink's ``parse_char`` path, which ``parse_buffer`` is, so a
  hostile stream is handled exactly as before: BAD_DATA for garbage and bad checksums, resynchronisation, and the
  same exceptions for the caller to catch.

It returns a list (empty when nothing completed), never None.
"""

from __future__ import annotations

import sys

from link.wire import CHECKSUM, HEADER_V2, IFLAG_SIGNED, SIGNATURE_BLOCK, STX_V2


def _one_frame(data) -> bool:
    """Whether ``data`` is exactly one MAVLink 2 frame by its length fields (its content is decode's to judge)."""
    n = len(data)
    if n < HEADER_V2 + CHECKSUM or data[0] != STX_V2:
        return False
    flags = data[2]
    if flags & ~IFLAG_SIGNED:
        return False  # unknown incompatibility flags: the slow path reports them as BAD_DATA
    return n == HEADER_V2 + data[1] + CHECKSUM + (SIGNATURE_BLOCK if flags & IFLAG_SIGNED else 0)


def read_frames(parser, data) -> list:
    """The messages in ``data`` (BAD_DATA included, as pymavlink's robust parser gives them), in order."""
    if not parser.robust_parsing:
        return parser.parse_buffer(data) or []  # (its prefix-error latch is pymavlink's business)
    if parser.callback is None and parser.buf_len() == 0 and _one_frame(data):
        return [_decode_one(parser, data)]
    m = parser.parse_char(data)
    if m is None:
        return []
    out = [m]
    while parser.buf_len() > 0:  # more bytes after the first frame (on an empty buffer parse_char finds nothing)
        m = parser.parse_char(b"")
        if m is None:
            break
        out.append(m)
    return out


def read_datagram(parser, data) -> list:
    """``read_frames`` of one whole datagram: bytes left unfinished at its end (a start-of-frame byte and a header
    whose length runs past the datagram: garbage, or a frame cut short) come back as one more BAD_DATA and the
    parser starts the next datagram empty.

    Why: pymavlink's parser is a stream parser (and ``read_frames`` answers exactly as it does). Kept, such a tail
    took the first bytes of the next datagram as the rest of its frame, failed the CRC and swallowed that
    datagram's valid frame: one stray datagram cost the owner's next command. Both ends read datagrams (UDP, the
    simulator's bus; serial links are cut into whole frames first: ``vehicle.companion.links``)."""
    out = read_frames(parser, data)
    if parser.robust_parsing and parser.buf_len() > 0:
        out.append(_drop_tail(parser))
    return out


def _drop_tail(parser):
    """The unfinished tail of a datagram, taken out of ``parser`` as BAD_DATA (see ``read_frames``)."""
    mod = sys.modules[type(parser).__module__]  # the generated dialect module: its BAD_DATA
    tail = parser.buf[parser.buf_index:]
    parser.buf = bytearray()
    parser.buf_index = 0
    parser.expected_length = HEADER_V2 + CHECKSUM
    parser.total_receive_errors += 1
    return mod.MAVLink_bad_data(tail, "unfinished frame at the end of a datagram")


def _decode_one(parser, data):
    """``parse_char(data)`` for a datagram that is one frame and an empty parser, without the state machine: the
    same decode, the same message or BAD_DATA, the same counters."""
    frame = bytearray(data)
    parser.total_bytes_received += len(frame)
    parser.have_prefix_error = False
    parser.expected_length = HEADER_V2 + CHECKSUM
    mod = sys.modules[type(parser).__module__]  # the generated dialect module: its MAVError and BAD_DATA
    try:
        m = parser.decode(frame)
    except mod.MAVError as reason:
        m = mod.MAVLink_bad_data(frame, reason.message)
        parser.total_receive_errors += 1
    parser.total_packets_received += 1
    return m

