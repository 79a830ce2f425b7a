"""Files kept on disk (a vehicle's parameters, key, timestamp and epochs; a station's downloads; results): written
atomically, read strictly.

A robot can lose power at any instant, and a half-written parameter file that boots with defaults silently loses
every setting the operator made (docs/architecture.md §8). So every file is replaced by write -> fsync -> rename ->
fsync of the directory: a reader, or the next boot, sees either the whole old file or the whole new one, never a
truncated one. Reading is the other half: a damaged file is reported by name and line (``StoredFileError``) and the
caller refuses to start on it rather than falling back to defaults.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


class StoredFileError(ValueError):
    """A file the vehicle keeps is missing a part, damaged or unreadable: ``path:line: what``."""

    def __init__(self, path: str | os.PathLike, line: int | None, what: str) -> None:
        self.path, self.line, self.what = str(path), line, what
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {what}")


def write_atomic(path: str | os.PathLike, data: str | bytes, mode: int = 0o644) -> None:
    """Replace ``path`` with ``data`` so that no reader and no crash ever sees a partial file.

    The temporary file is created beside the target (same file system, so the rename is atomic) with ``mode``
    from the start: a secret key is never readable by others, not even for an instant.
    """
    target = Path(path)
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    directory = target.parent if str(target.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    try:
        os.fchmod(fd, mode)
        view = memoryview(raw)
        while view:
            written = os.write(fd, view)
            view = view[written:]
        os.fsync(fd)
    except BaseException:
        os.close(fd)
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    os.close(fd)
    try:
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_dir(directory)


def remove_leftovers(path: str | os.PathLike) -> int:
    """Delete the temporary files a crash left beside ``path`` mid-write (``write_atomic``'s ``.NAME.*.tmp``).

    Call at boot, before anything writes ``path``: the kept file itself is whole either way, this only stops
    every crash from leaving one more orphan. Returns how many were removed."""
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    removed = 0
    for tmp in directory.glob(f".{target.name}.*.tmp"):
        with contextlib.suppress(OSError):
            tmp.unlink()
            removed += 1
    return removed


def _fsync_dir(directory: Path) -> None:
    """Make the rename itself durable (POSIX); harmless where directories cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def read_text(path: str | os.PathLike) -> str:
    """A kept file's text, or StoredFileError naming it (unreadable, not UTF-8)."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise StoredFileError(path, None, f"not UTF-8 text ({e.reason})") from None
    except OSError as e:
        raise StoredFileError(path, None, e.strerror or str(e)) from None
