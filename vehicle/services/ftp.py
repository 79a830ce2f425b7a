"""MAVLink FTP (FILE_TRANSFER_PROTOCOL), read-only: the files a vehicle offers its ground stations.

The vehicle shares no file system; it has a few things worth fetching as files, made on request: the link map
(``linkmap.csv``, docs/architecture.md §6). MAVLink FTP is how ground stations already fetch files (MAVProxy's
``ftp get``, QGroundControl's file manager, pymavlink's ``mavftp``), so the map needs no message of its own.

Served: ListDirectory of the root, OpenFileRO (the file is made then, and that snapshot is what the session reads,
so a read never mixes two versions of the map), ReadFile, BurstReadFile, TerminateSession, ResetSessions.
Everything that writes is refused with FileProtected; a path not offered gets FileNotFound (MAVProxy asks for
``@PARAM/param.pck`` first and falls back to the parameter protocol on it); an opcode not known, UnknownCommand.
A request repeated with the same sequence number gets the same answer again and is not executed twice (the
protocol's retry rule). The payload layout is ``link.ftp``.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping

from link import ftp
from link.ftp import DATA, OP_ACK, OP_BURST_READ_FILE, OP_LIST_DIRECTORY, OP_NAK, OP_OPEN_FILE_RO, encode, path_of
from vehicle.services.base import Outbox, Service, Source, handles

MAX_SESSIONS = 4  # open files at once (each holds one snapshot of its file)
BURST_PACKETS = 32  # packets one BurstReadFile sends at most before the client asks for the rest

Files = Mapping[str, Callable[[], bytes]]  # file name -> what makes its content (called at OpenFileRO)


class FtpServer(Service):
    """The read-only files of one component, ``files`` (an empty table: every path is not found)."""

    def __init__(self, out: Outbox, files: Files | None = None) -> None:
        self.out = out
        self.files: Files = {} if files is None else files
        self.sessions: dict[int, bytes] = {}  # session id -> the snapshot it reads
        self.answered: dict[tuple[int, int], tuple[int, list[list[int]]]] = {}  # station -> (its seq, its answer)

    @handles("FILE_TRANSFER_PROTOCOL")
    def _on_ftp(self, m, src: Source, t: float) -> None:
        p = ftp.decode(m.payload)
        if p is None or p.opcode >= OP_ACK:
            return  # too short to be a request, or an ACK or NAK itself: never answer an answer
        station = (src.sysid, src.compid)
        last = self.answered.get(station)
        if last is not None and last[0] == p.seq:
            replies = last[1]  # a retry: the same answer, the request not executed twice
        else:
            replies = self._answer(p)
            self.answered[station] = (p.seq, replies)
        for reply in replies:
            self.out.mav.file_transfer_protocol_send(0, src.sysid, src.compid, reply)

    def _answer(self, p: ftp.Packet) -> list[list[int]]:
        op = p.opcode
        if op == ftp.OP_NONE:
            return [ack(p)]
        if op == ftp.OP_TERMINATE_SESSION:
            return [ack(p) if self.sessions.pop(p.session, None) is not None else nak(p, ftp.ERR_INVALID_SESSION)]
        if op == ftp.OP_RESET_SESSIONS:
            self.sessions.clear()
            return [ack(p)]
        if op == OP_LIST_DIRECTORY:
            return [self._list(p)]
        if op == OP_OPEN_FILE_RO:
            return [self._open(p)]
        if op == ftp.OP_READ_FILE:
            return [self._read(p)]
        if op == OP_BURST_READ_FILE:
            return self._burst(p)
        if op in ftp.WRITES:
            return [nak(p, ftp.ERR_FILE_PROTECTED)]
        return [nak(p, ftp.ERR_UNKNOWN_COMMAND)]

    def _list(self, p: ftp.Packet) -> list[int]:
        """Entries of the root from entry ``offset`` on, as many as fit: ``F<name>\\t<size>\\0`` each."""
        if path_of(p.data) not in ("", "."):
            return nak(p, ftp.ERR_FILE_NOT_FOUND)
        names = sorted(self.files)
        if p.offset >= len(names):
            return nak(p, ftp.ERR_EOF)
        out = b""
        for name in names[p.offset:]:
            entry = f"F{name}\t{len(self.files[name]())}".encode() + b"\0"
            if len(out) + len(entry) > DATA:
                break
            out += entry
        return ack(p, out, p.offset)

    def _open(self, p: ftp.Packet) -> list[int]:
        make = self.files.get(path_of(p.data))
        if make is None:
            return nak(p, ftp.ERR_FILE_NOT_FOUND)
        if len(self.sessions) >= MAX_SESSIONS:
            return nak(p, ftp.ERR_NO_SESSIONS)
        # the client's own session number when it is free (ArduPilot's server keeps it, and MAVProxy ignores an
        # answer for another session), else the lowest free one (what PX4's server hands out)
        free = p.session if p.session not in self.sessions else min(set(range(256)) - set(self.sessions))
        try:
            content = make()
        except Exception:  # noqa: BLE001 - a file that cannot be made now is a failed open, never a fault
            return nak(p, ftp.ERR_FAIL)
        self.sessions[free] = content
        return encode(p.seq + 1, free, OP_ACK, struct.pack("<I", len(content)), 0, p.opcode)

    def _read(self, p: ftp.Packet) -> list[int]:
        content = self.sessions.get(p.session)
        if content is None:
            return nak(p, ftp.ERR_INVALID_SESSION)
        if p.offset >= len(content):
            return nak(p, ftp.ERR_EOF, p.offset)
        return ack(p, content[p.offset:p.offset + min(_size(p), DATA)], p.offset)

    def _burst(self, p: ftp.Packet) -> list[list[int]]:
        """Packets from the offset on, each with the next sequence number, the last marked burst complete; the
        end of the file ends the burst with NAK EOF at the file's length, as ArduPilot's server ends one."""
        content = self.sessions.get(p.session)
        if content is None:
            return [nak(p, ftp.ERR_INVALID_SESSION)]
        step, offset = min(_size(p), DATA), p.offset
        replies = []
        for k in range(BURST_PACKETS):
            if offset >= len(content):
                replies.append(encode(p.seq + 1 + k, p.session, OP_NAK, bytes((ftp.ERR_EOF,)), offset, p.opcode,
                                      burst_complete=True))
                break
            replies.append(encode(p.seq + 1 + k, p.session, OP_ACK, content[offset:offset + step], offset, p.opcode,
                                  burst_complete=k == BURST_PACKETS - 1))
            offset = min(offset + step, len(content))
        return replies


def _size(p: ftp.Packet) -> int:
    """The data size a read asks for: its size field (which ``decode`` cut its data to); 0, a full packet."""
    return len(p.data) or DATA


def ack(p: ftp.Packet, data: bytes = b"", offset: int = 0) -> list[int]:
    return encode(p.seq + 1, p.session, OP_ACK, data, offset, p.opcode)


def nak(p: ftp.Packet, error: int, offset: int = 0) -> list[int]:
    return encode(p.seq + 1, p.session, OP_NAK, bytes((error,)), offset, p.opcode)
