"""The connections named on the command line (docs/architecture.md §11 CONN): serial, TCP client, UDP in and
UDP out; one to the autopilot and one or more to the ground (§11.1).

``parse_conn`` checks a connection string before anything opens (a bad one is a usage error, exit 2); ``open_link``
opens it. A link moves bytes and nothing else: ``read()`` gives what arrived (with where from), ``write`` sends,
``fileno`` lets the loop wait on it. A TCP link that drops reconnects by itself on ``poll``, as the autopilot's
serial port or SITL may come back. A link never raises on a failed write: it counts it (``errors``,
``last_error``) so the loop can report it while the other links carry on.

``Framer`` cuts a byte stream into MAVLink frames: several ground links feed one parser in the companion, and a
serial read may end mid-frame, so each link's bytes are handed over in whole frames; the telemetry log is per frame
too.
"""

from __future__ import annotations

import contextlib
import errno
import os
import socket
import termios
import time
from collections.abc import Hashable
from dataclasses import dataclass

from link.transports import UdpTransport

KINDS = ("serial", "tcp", "udpin", "udpout")
DEFAULT_BAUD = 57600
RECONNECT_EVERY = 1.0  # s between attempts on a TCP link that dropped


class ConnError(ValueError):
    """A connection string that cannot be a connection, or one that cannot be opened."""


class Counted:
    """Failures of a link, counted rather than raised: one broken ground link must not stop the others."""

    errors = 0
    last_error = ""

    def _failed(self, e: OSError) -> None:
        self.errors += 1
        self.last_error = e.strerror or str(e)


@dataclass(frozen=True)
class Conn:
    text: str
    kind: str
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0


def parse_conn(text: str) -> Conn:
    """``serial:DEVICE[:BAUD]``, ``tcp:HOST:PORT``, ``udpin:HOST:PORT`` or ``udpout:HOST:PORT`` (pymavlink's
    forms; ``udp:`` is ``udpin:``); ConnError saying what is wrong otherwise."""
    kind, sep, rest = text.partition(":")
    kind = "udpin" if kind == "udp" else kind
    if not sep or kind not in KINDS or not rest:
        raise ConnError(f"{text!r} is not a connection: use serial:DEVICE:BAUD, tcp:HOST:PORT, udpin:HOST:PORT "
                        f"or udpout:HOST:PORT")
    if kind == "serial":
        device, sep, baud = rest.rpartition(":")
        if not sep or not device:
            device, baud = rest, str(DEFAULT_BAUD)
        if not baud.isdigit() or not 50 <= int(baud) <= 4_000_000 or not hasattr(termios, f"B{baud}"):
            raise ConnError(f"{text!r}: {baud!r} is not a serial speed this system knows (e.g. 57600, 921600)")
        return Conn(text, kind, device=device, baud=int(baud))
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit() or not (0 if kind == "udpin" else 1) <= int(port) <= 65535:
        raise ConnError(f"{text!r}: needs HOST:PORT with a port of 1..65535")
    if not host and kind in ("tcp", "udpout"):
        raise ConnError(f"{text!r}: needs a host to connect to")
    return Conn(text, kind, host=host or "0.0.0.0", port=int(port))


def require_device(conn: Conn) -> None:
    """ConnError naming ``conn`` if it is a serial device that does not exist: checked with the command line, before
    anything connects, so a mistyped radio is not found only after the autopilot's wait."""
    if conn.kind == "serial" and not os.path.exists(conn.device):
        raise ConnError(f"cannot open {conn.text}: no such device {conn.device}")


class TcpLink(Counted):
    """A TCP client (SITL's SERIALn, a telemetry bridge); reconnects on ``poll`` after a drop."""

    def __init__(self, conn: Conn, timeout: float = 5.0) -> None:
        self.conn = conn
        self.sock: socket.socket | None = None
        self.next_try = 0.0
        self.drops = 0
        self._connect(timeout)  # the first time the error goes to the caller: an unreachable autopilot is fatal
        if self.sock is None:
            raise ConnError(f"cannot connect to {conn.text}")

    def _connect(self, timeout: float) -> None:
        s = socket.create_connection((self.conn.host, self.conn.port), timeout=timeout)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        s.setblocking(False)
        self.sock = s

    @property
    def up(self) -> bool:
        return self.sock is not None

    def fileno(self) -> int | None:
        return self.sock.fileno() if self.sock is not None else None

    def read(self) -> list[tuple[bytes, Hashable | None]]:
        if self.sock is None:
            return []
        try:
            data = self.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return []
        except OSError:
            data = b""
        if not data:
            self._drop()
            return []
        return [(data, None)]

    def write(self, data: bytes) -> None:
        if self.sock is None:
            return
        try:
            self.sock.sendall(data)
        except (BlockingIOError, InterruptedError):
            pass  # the far end is not reading: telemetry is dropped rather than queued without bound
        except OSError as e:
            self._failed(e)
            self._drop()

    def _drop(self) -> None:
        if self.sock is not None:
            self.sock.close()
        self.sock = None
        self.drops += 1
        self.next_try = time.monotonic() + RECONNECT_EVERY

    def poll(self) -> None:
        """Reconnect a dropped link, at most every RECONNECT_EVERY s (the attempt itself waits 0.2 s at most)."""
        if self.sock is not None or time.monotonic() < self.next_try:
            return
        self.next_try = time.monotonic() + RECONNECT_EVERY
        with contextlib.suppress(OSError):
            self._connect(0.2)

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None


class UdpLink(Counted):
    """UDP: ``udpin`` listens and answers whoever talked to it; ``udpout`` sends to one address first."""

    def __init__(self, conn: Conn, pinned=None) -> None:
        self.conn = conn
        try:
            if conn.kind == "udpin":
                self.transport = UdpTransport((conn.host, conn.port), pinned=pinned)
            else:
                self.transport = UdpTransport(("0.0.0.0", 0), ((conn.host, conn.port),), pinned=pinned)
        except OSError as e:
            raise ConnError(f"cannot open {conn.text}: {e.strerror or e}") from None
        self.up = True

    def fileno(self) -> int | None:
        return self.transport.sock.fileno()

    def read(self) -> list[tuple[bytes, Hashable | None]]:
        return list(self.transport.receive())

    def write(self, data: bytes) -> None:
        """To every peer, as ``UdpTransport.send``, but a failure (network down, no route) is counted, not hidden:
        nobody listening yet (refused) and a full socket buffer are UDP telemetry's normal losses."""
        tr = self.transport
        pinned = list(tr.pinned()) if tr.pinned is not None else []
        for addr in dict.fromkeys([*tr.fixed, *tr.learned, *pinned]):
            try:
                tr.sock.sendto(data, addr)
            except (ConnectionRefusedError, BlockingIOError, InterruptedError):
                pass
            except OSError as e:
                self._failed(e)

    def poll(self) -> None:
        pass

    def close(self) -> None:
        self.transport.close()


class SerialLink(Counted):
    """A serial port in raw mode (the autopilot's TELEM port, or the radio's)."""

    def __init__(self, conn: Conn) -> None:
        self.conn = conn
        self.fd: int | None = None
        self.next_try = 0.0
        try:
            self._open()
        except (OSError, termios.error) as e:
            raise ConnError(f"cannot open {conn.text}: {getattr(e, 'strerror', None) or e}") from None
        self.up = True

    def _open(self) -> None:
        fd = os.open(self.conn.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            attrs = termios.tcgetattr(fd)
            speed = getattr(termios, f"B{self.conn.baud}")
            attrs[0] = 0  # iflag: no translation, no flow control
            attrs[1] = 0  # oflag: raw output
            attrs[2] = termios.CS8 | termios.CREAD | termios.CLOCAL
            attrs[3] = 0  # lflag: no echo, no canonical mode, no signals
            attrs[4] = attrs[5] = speed
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
        except termios.error:
            os.close(fd)
            raise
        self.fd = fd

    def fileno(self) -> int | None:
        return self.fd

    def read(self) -> list[tuple[bytes, Hashable | None]]:
        if self.fd is None:
            return []
        try:
            data = os.read(self.fd, 65536)
        except BlockingIOError:
            return []
        except OSError as e:
            if e.errno in (errno.EAGAIN, errno.EINTR):
                return []
            self._failed(e)
            self._drop()  # unplugged: the loop reports the silence, ``poll`` opens it again when it is back
            return []
        return [(data, None)] if data else []

    def _drop(self) -> None:
        if self.fd is not None:
            with contextlib.suppress(OSError):
                os.close(self.fd)
        self.fd = None
        self.up = False
        self.next_try = time.monotonic() + RECONNECT_EVERY

    def write(self, data: bytes) -> None:
        if self.fd is None:
            return
        try:
            os.write(self.fd, data)
        except BlockingIOError:
            pass  # the port's buffer is full: dropped rather than queued without bound
        except OSError as e:
            self._failed(e)
            self._drop()

    def poll(self) -> None:
        """Open a port that went away again (a USB adapter unplugged and back), at most every RECONNECT_EVERY s."""
        if self.fd is not None or time.monotonic() < self.next_try:
            return
        self.next_try = time.monotonic() + RECONNECT_EVERY
        with contextlib.suppress(OSError, termios.error):
            self._open()
            self.up = True

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def open_link(conn: Conn, pinned=None, timeout: float = 5.0) -> TcpLink | UdpLink | SerialLink:
    """Open ``conn``; ConnError naming it if it cannot be (OSError from a TCP connect is the caller's, who may
    retry while an autopilot boots)."""
    if conn.kind == "tcp":
        return TcpLink(conn, timeout)
    if conn.kind == "serial":
        return SerialLink(conn)
    return UdpLink(conn, pinned)


MAGIC_V1, MAGIC_V2 = 0xFE, 0xFD


class Framer:
    """Cuts bytes into MAVLink frames by their headers alone (length, signed flag), as pymavlink's parser and
    mavlogdump frame them, so what it cuts they read back frame for frame; no CRC (the dialect's CRC extras are the
    parser's business, and a frame with a bad one is still what was on the wire).

    ``feed`` returns whole frames and runs of bytes that are no frame (line noise, kept so the companion still
    counts them), in order. A stream (serial, TCP) keeps an incomplete frame for the next read; a datagram link
    drops it, since the next datagram (maybe from someone else) never completes it."""

    def __init__(self, stream: bool = True) -> None:
        self.stream = stream
        self.buf = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        buf = self.buf
        buf += data
        out: list[bytes] = []
        i, n = 0, len(buf)
        while i < n:
            if buf[i] not in (MAGIC_V1, MAGIC_V2):
                j = min((k for k in (buf.find(MAGIC_V1, i), buf.find(MAGIC_V2, i)) if k >= 0), default=n)
                out.append(bytes(buf[i:j]))
                i = j
                continue
            if n - i < 3:
                break
            size = buf[i + 1] + (8 if buf[i] == MAGIC_V1 else 12 + (13 if buf[i + 2] & 1 else 0))
            if n - i < size:
                break
            out.append(bytes(buf[i:i + size]))
            i += size
        if self.stream:
            del buf[:i]
        else:
            buf.clear()
        return out


def is_frame(piece: bytes) -> bool:
    """Whether a piece ``Framer.feed`` returned is a frame (not a run of noise)."""
    return bool(piece) and piece[0] in (MAGIC_V1, MAGIC_V2)
