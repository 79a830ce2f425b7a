"""MAVLink FTP (FILE_TRANSFER_PROTOCOL), refused at once: this vehicle has no file server.

Ground stations that try FTP first (MAVProxy fetches parameters with it) would otherwise wait for their time-out
before falling back to the parameter protocol; a NAK "unknown command" sends them there at once. The FTP opcodes
and error codes are the microservice's own (its payload layout, not a dialect enum), named here.
"""

from __future__ import annotations

import struct

from vehicle.services.base import Outbox, Service, Source, handles

OP_ACK, OP_NAK = 128, 129  # the answer opcodes; every opcode from OP_ACK up is an answer
ERR_UNKNOWN_COMMAND = 7
HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, padding, offset
PAYLOAD = 251  # bytes of FILE_TRANSFER_PROTOCOL.payload


class FtpRefusal(Service):
    """Every FTP request answered with NAK (unknown command)."""

    def __init__(self, out: Outbox) -> None:
        self.out = out

    @handles("FILE_TRANSFER_PROTOCOL")
    def _on_ftp(self, m, src: Source, t: float) -> None:
        payload = bytes(m.payload)
        if len(payload) < HEADER.size:
            return
        seq, session, opcode = HEADER.unpack_from(payload)[:3]
        if opcode >= OP_ACK:
            return  # an ACK or NAK itself: never answer an answer
        nak = HEADER.pack((seq + 1) & 0xFFFF, session, OP_NAK, 1, opcode, 0, 0, 0) + bytes([ERR_UNKNOWN_COMMAND])
        self.out.mav.file_transfer_protocol_send(0, src.sysid, src.compid, nak + bytes(PAYLOAD - len(nak)))
