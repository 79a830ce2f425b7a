"""The MAVLink FTP payload: what both ends of a file transfer put inside FILE_TRANSFER_PROTOCOL.payload.

The microservice defines its own header, opcodes and error codes (they are not a dialect enum), so the vehicle's
file server (``vehicle/services/ftp.py``), the companion's router and the ground station's file client
(``gcs/file_transfer.py``) read them from this one place. Layout: sequence number (2), session (1), opcode (1),
data size (1), the request's opcode in an answer (1), burst complete (1), padding (1), offset (4), data (239).
"""

from __future__ import annotations

import struct
from typing import NamedTuple

HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, padding, offset
PAYLOAD = 251  # bytes of FILE_TRANSFER_PROTOCOL.payload
DATA = PAYLOAD - HEADER.size  # 239 bytes of data per packet

# request opcodes
OP_NONE, OP_TERMINATE_SESSION, OP_RESET_SESSIONS, OP_LIST_DIRECTORY, OP_OPEN_FILE_RO, OP_READ_FILE = 0, 1, 2, 3, 4, 5
OP_CREATE_FILE, OP_WRITE_FILE, OP_REMOVE_FILE, OP_CREATE_DIRECTORY, OP_REMOVE_DIRECTORY = 6, 7, 8, 9, 10
OP_OPEN_FILE_WO, OP_TRUNCATE_FILE, OP_RENAME, OP_CALC_FILE_CRC32, OP_BURST_READ_FILE = 11, 12, 13, 14, 15
OP_ACK, OP_NAK = 128, 129  # the answer opcodes; every opcode from OP_ACK up is an answer
# the requests that only read (the rest create, write, remove or rename)
READS = frozenset((OP_NONE, OP_TERMINATE_SESSION, OP_RESET_SESSIONS, OP_LIST_DIRECTORY, OP_OPEN_FILE_RO,
                   OP_READ_FILE, OP_CALC_FILE_CRC32, OP_BURST_READ_FILE))
WRITES = frozenset((OP_CREATE_FILE, OP_WRITE_FILE, OP_REMOVE_FILE, OP_CREATE_DIRECTORY, OP_REMOVE_DIRECTORY,
                    OP_OPEN_FILE_WO, OP_TRUNCATE_FILE, OP_RENAME))

# NAK error codes (the first data byte of a NAK)
ERR_FAIL, ERR_INVALID_DATA_SIZE, ERR_INVALID_SESSION, ERR_NO_SESSIONS, ERR_EOF = 1, 3, 4, 5, 6
ERR_UNKNOWN_COMMAND, ERR_FILE_EXISTS, ERR_FILE_PROTECTED, ERR_FILE_NOT_FOUND = 7, 8, 9, 10
ERRORS = {ERR_FAIL: "failed", ERR_INVALID_DATA_SIZE: "invalid data size", ERR_INVALID_SESSION: "invalid session",
          ERR_NO_SESSIONS: "no sessions available", ERR_EOF: "end of file", ERR_UNKNOWN_COMMAND: "unknown command",
          ERR_FILE_EXISTS: "file exists", ERR_FILE_PROTECTED: "file protected",
          ERR_FILE_NOT_FOUND: "file not found"}


class Packet(NamedTuple):
    """One FTP payload, decoded."""

    seq: int
    session: int
    opcode: int
    req_opcode: int
    burst_complete: bool
    offset: int
    data: bytes

    @property
    def error(self) -> int | None:
        """A NAK's error code (None for anything else, or a NAK without one)."""
        return self.data[0] if self.opcode == OP_NAK and self.data else None


def encode(seq: int, session: int, opcode: int, data: bytes = b"", offset: int = 0, req_opcode: int = 0,
           burst_complete: bool = False) -> list[int]:
    """A payload as pymavlink's ``file_transfer_protocol_send`` takes it (zero-padded to PAYLOAD bytes)."""
    if len(data) > DATA:
        raise ValueError(f"FTP data of {len(data)} bytes (at most {DATA})")
    head = HEADER.pack(seq & 0xFFFF, session, opcode, len(data), req_opcode, int(burst_complete), 0, offset)
    return list(head + data + bytes(DATA - len(data)))


def decode(payload) -> Packet | None:
    """A payload as received (None if it is too short to hold a header)."""
    raw = bytes(payload)
    if len(raw) < HEADER.size:
        return None
    seq, session, opcode, size, req, burst, _, offset = HEADER.unpack_from(raw)
    return Packet(seq, session, opcode, req, bool(burst), offset, raw[HEADER.size:HEADER.size + min(size, DATA)])


def path_of(data: bytes) -> str:
    """The path a request names: up to the first NUL, without a leading ``/``."""
    return data.split(b"\0", 1)[0].decode("utf-8", "replace").strip().lstrip("/")
