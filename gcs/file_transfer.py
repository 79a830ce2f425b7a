"""The ground side of MAVLink FTP, read only: fetch one file from the vehicle (the link map, ``linkmap.csv``).

OpenFileRO, then ReadFile from offset 0 until the size the open reported, then TerminateSession. One request is
outstanding at a time, so a lossy radio costs retries, never a corrupt file: an answer is believed only if it
carries the sequence number one past the request's and the request's opcode; a request that hears nothing for
``FILE_TIMEOUT`` is sent again with the same sequence number (the server answers a repeat without executing it
twice), and the download gives up after ``FILE_TRIES``. Like the station it has no clock and no socket.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from link import ftp

FILE_TIMEOUT = 1.0  # s without an answer before the request is sent again
FILE_TRIES = 5


@dataclass
class Download:
    """A file being fetched."""

    path: str
    last_at: float
    tries: int = 1
    session: int | None = None
    size: int | None = None  # what the open said
    data: bytearray = field(default_factory=bytearray)
    done: bool = False
    error: str | None = None  # why it failed (None: it did not, or it is not done)

    @property
    def ok(self) -> bool:
        return self.done and self.error is None


class FileClient:
    """One station's file downloads from one vehicle component (``target``/``target_comp``), encoded by ``mav``."""

    def __init__(self, mav, target: int, target_comp: int) -> None:
        self.mav, self.target, self.target_comp = mav, target, target_comp
        self.seq = 0
        self.request: list[int] | None = None  # the outstanding request's payload (sent again on a time-out)
        self.download: Download | None = None

    def get(self, path: str, t: float) -> Download:
        """Start fetching ``path`` (a download in progress is abandoned)."""
        self.download = Download(path, t)
        self._send(ftp.OP_OPEN_FILE_RO, path.encode() + b"\0")
        return self.download

    def tick(self, t: float) -> None:
        d = self.download
        if d is None or d.done or self.request is None or t - d.last_at < FILE_TIMEOUT:
            return
        if d.tries >= FILE_TRIES:
            self._fail(f"no answer after {FILE_TRIES} tries")
            return
        d.tries += 1
        d.last_at = t
        self._transmit()

    def on_file_transfer_protocol(self, m, t: float) -> None:
        d, p = self.download, ftp.decode(m.payload)
        if d is None or d.done or p is None or self.request is None or p.opcode < ftp.OP_ACK:
            return
        if p.seq != (self.seq + 1) & 0xFFFF or p.req_opcode != self.request[3]:
            return  # an answer to an earlier request (a retry's twin): already dealt with
        d.last_at, d.tries = t, 1
        if p.req_opcode == ftp.OP_OPEN_FILE_RO:
            self._opened(d, p)
        elif p.req_opcode == ftp.OP_READ_FILE:
            self._read(d, p)
        elif p.req_opcode == ftp.OP_TERMINATE_SESSION:
            d.done, self.request = True, None

    def _opened(self, d: Download, p: ftp.Packet) -> None:
        if p.opcode == ftp.OP_NAK:
            self._fail(ftp.ERRORS.get(p.error or 0, "refused"))
            return
        if len(p.data) < 4:
            self._fail("the open carried no size")
            return
        d.session, d.size = p.session, struct.unpack_from("<I", p.data)[0]
        self._next_read(d)

    def _read(self, d: Download, p: ftp.Packet) -> None:
        if p.opcode == ftp.OP_NAK:
            if p.error == ftp.ERR_EOF:
                self._finish(d)
            else:
                self._fail(f"{ftp.ERRORS.get(p.error or 0, 'refused')} at byte {len(d.data)}")
            return
        if p.offset != len(d.data) or not p.data:
            self._fail(f"data for byte {p.offset} when byte {len(d.data)} was asked")
            return
        d.data += p.data
        self._next_read(d)

    def _next_read(self, d: Download) -> None:
        if d.size is not None and len(d.data) >= d.size:
            self._finish(d)
            return
        self._send(ftp.OP_READ_FILE, bytes(ftp.DATA), offset=len(d.data), session=d.session or 0)

    def _finish(self, d: Download) -> None:
        if d.size is not None and len(d.data) != d.size:
            self._fail(f"{len(d.data)} bytes of {d.size}")
            return
        self._send(ftp.OP_TERMINATE_SESSION, session=d.session or 0)
        d.done = True  # the file is whole; the session's end is a courtesy, not waited for

    def _fail(self, why: str) -> None:
        d = self.download
        assert d is not None
        d.done, d.error = True, why
        if d.session is not None:  # the vehicle still holds the file open: end the session (not waited for)
            self._send(ftp.OP_TERMINATE_SESSION, session=d.session)
        self.request = None

    def _send(self, opcode: int, data: bytes = b"", offset: int = 0, session: int = 0) -> None:
        self.seq = (self.seq + 2) & 0xFFFF  # past the previous request and its answer
        self.request = ftp.encode(self.seq, session, opcode, data, offset)
        self._transmit()

    def _transmit(self) -> None:
        self.mav.file_transfer_protocol_send(0, self.target, self.target_comp, self.request)
