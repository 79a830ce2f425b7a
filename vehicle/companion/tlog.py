"""``--log DIR``: every frame the companion moves, both ways, in a MAVLink telemetry log (docs/architecture.md §11.1).

The format is the one MAVProxy writes and mavlogdump, MAVExplorer and QGC read: per frame, an 8-byte big-endian
count of microseconds since the Unix epoch, then the frame's bytes. Readers take exactly one frame after each
timestamp, so chunks (a serial read, several frames in one write) are cut into frames first (``links.Framer``).

The two low bits of each timestamp say which way the frame went, as MAVProxy uses them for the link number (pymavlink
gives them back as ``msg._link``): 0 from the autopilot, 1 from the ground, 2 to the ground, 3 to the autopilot
(MAVProxy's mark for what it sent to the vehicle).

A log is a record, not a duty: a write that fails (a full disk) is reported once and ends the log, and the companion
routes on. Writes are buffered and flushed every FLUSH_EVERY s, so the log costs no disk write per frame.
"""

from __future__ import annotations

import contextlib
import struct
import time
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import BinaryIO

from vehicle.companion.links import Framer, is_frame

FROM_AUTOPILOT, FROM_GROUND, TO_GROUND, TO_AUTOPILOT = 0, 1, 2, 3
FLUSH_EVERY = 1.0  # s
_STAMP = struct.Struct(">Q")


class TlogError(ValueError):
    """A log directory the companion cannot write a log in (exit 2 at start)."""


def log_name(start: float) -> str:
    """The file name for a log started at Unix time ``start``: its UTC time, sortable, no colons (FAT, Windows)."""
    return datetime.fromtimestamp(start, timezone.utc).strftime("%Y-%m-%dT%H-%M-%SZ")


class Tlog:
    """One telemetry log. ``create`` makes a new file in a directory; ``write(direction, data)`` records the frames
    in ``data``; ``failed`` says why logging stopped, if it did."""

    def __init__(self, f: BinaryIO, path: Path, clock: Callable[[], float] = time.time) -> None:
        self.f: BinaryIO | None = f
        self.path = path
        self.clock = clock
        self.framers = {d: Framer() for d in (FROM_AUTOPILOT, FROM_GROUND, TO_GROUND, TO_AUTOPILOT)}
        self.frames = 0
        self.failed: str | None = None
        self.flushed_at = time.monotonic()  # (not the wall clock: setting it back must not stop the flushes)

    @classmethod
    def create(cls, directory: Path, clock: Callable[[], float] = time.time) -> Tlog:
        """A new log ``DIRECTORY/<UTC start>.tlog`` (``-1``, ``-2``... if one of that second exists: a log is never
        overwritten), the directory made if need be. TlogError naming the directory if it cannot be written."""
        start = clock()
        try:
            directory.mkdir(parents=True, exist_ok=True)
            for n in range(1000):
                path = directory / f"{log_name(start)}{f'-{n}' if n else ''}.tlog"
                try:
                    return cls(path.open("xb"), path, clock)
                except FileExistsError:
                    continue
        except FileExistsError:
            raise TlogError(f"--log {directory}: not a directory") from None
        except OSError as e:
            raise TlogError(f"--log {directory}: cannot write a log there: {e.strerror or e}") from None
        raise TlogError(f"--log {directory}: too many logs started at {log_name(start)}")

    def write(self, direction: int, data: bytes) -> None:
        """Record the frames of ``data`` (bytes that are no frame are left out: a reader would lose its place)."""
        if self.f is None:
            return
        usec = (int(self.clock() * 1e6) & ~3) | direction
        stamp = _STAMP.pack(usec)
        frames = [p for p in self.framers[direction].feed(data) if is_frame(p)]
        if not frames:
            return
        try:
            self.f.write(b"".join(stamp + frame for frame in frames))
        except OSError as e:
            self._stop(e)
            return
        self.frames += len(frames)

    def flush_if_due(self) -> None:
        """Flush at most every FLUSH_EVERY s (the loop calls this every step)."""
        now = time.monotonic()
        if self.f is None or now - self.flushed_at < FLUSH_EVERY:
            return
        self.flushed_at = now
        try:
            self.f.flush()
        except OSError as e:
            self._stop(e)

    def _stop(self, e: OSError) -> None:
        self.failed = f"log stopped: {e.strerror or e} ({self.path}); routing continues"
        f, self.f = self.f, None
        if f is not None:
            with contextlib.suppress(OSError):
                f.close()  # (it may try to write its buffer again and fail again)

    def close(self) -> None:
        """Flush and close; a log that recorded nothing is removed (a start that failed, or a restart loop, would
        otherwise leave an empty file each time)."""
        f, self.f = self.f, None
        if f is None:
            return
        try:
            f.close()
        except OSError as e:
            self.failed = self.failed or f"log {self.path}: {e.strerror or e} at close"
        if self.frames == 0 and self.failed is None:
            with contextlib.suppress(OSError):
                self.path.unlink()
