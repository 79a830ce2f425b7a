"""The vehicle's signing key and signing timestamp on disk (docs/architecture.md §4.1).

Two small files side by side: ``FILE`` holds the key (one line of 64 hex characters, mode 0600) and
``FILE.stamp`` the last signing timestamp the vehicle used. The timestamp file exists because a robot's clock is
not trustworthy after a reboot (no RTC, no GPS fix yet): if the vehicle restarted its timestamps from a clock that
went backwards, every ground station would drop its frames as replays, and worse, frames it signed before the
reboot would become replayable. So the timestamp is saved at least once a minute and at shutdown, and at boot the
vehicle continues from max(saved + 1, clock).

Both files are written with ``link.storage.write_atomic`` and read strictly: a damaged file names itself and
its line (``StoredFileError``) and the vehicle refuses to start rather than run unsigned or with a guessed clock.
Key parsing itself lives in ``link.signing`` so a ground station can read the same file without this package.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from link.signing import MAX_TIMESTAMP, Key, KeyFileError, format_key, parse_key
from link.storage import StoredFileError, read_text, write_atomic

KEY_MODE = 0o600
STAMP_SAVE_EVERY = 30.0  # s of vehicle time between timestamp saves: "at least once a minute", with margin


def stamp_path(key_path: str | os.PathLike) -> Path:
    return Path(f"{key_path}.stamp")


def read_key(path: str | os.PathLike) -> Key:
    try:
        return parse_key(read_text(path), path)
    except KeyFileError as e:
        raise StoredFileError(e.path, e.line, e.what) from None


def write_key(path: str | os.PathLike, key: Key, force: bool = False) -> None:
    """Write ``key`` with mode 0600; an existing file (someone's key) is never replaced unless ``force``."""
    if not force and os.path.lexists(path):
        raise FileExistsError(f"{path} exists; give --force to replace the key in it")
    write_atomic(path, format_key(key), mode=KEY_MODE)


def parse_stamp(text: str, path: str | os.PathLike) -> int:
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise StoredFileError(path, 1, "empty: expected the last signing timestamp (an integer)")
    try:
        value = int(lines[0].strip())
    except ValueError:
        raise StoredFileError(path, 1, f"{lines[0].strip()[:20]!r} is not an integer timestamp") from None
    if not 0 <= value <= MAX_TIMESTAMP:
        raise StoredFileError(path, 1, f"timestamp {value} outside 0..2^48-1")
    for n, extra in enumerate(lines[1:], start=2):
        if extra.strip():
            raise StoredFileError(path, n, "unexpected text after the timestamp")
    return value


def boot_stamp(saved: int | None, clock: int) -> int:
    """Where the signing timestamp continues after a boot: never behind anything already used."""
    return clock if saved is None else max(saved + 1, clock)


@dataclass
class KeyStore:
    """The key file and its timestamp file, as loaded at boot."""

    path: Path
    key: Key
    saved_stamp: int | None  # None: never saved (first boot with this key file)

    @classmethod
    def open(cls, path: str | os.PathLike) -> KeyStore:
        """Load the key and the last saved timestamp; StoredFileError (naming file and line) if either is bad."""
        p = Path(path)
        key = read_key(p)
        sp = stamp_path(p)
        saved = parse_stamp(read_text(sp), sp) if sp.exists() else None
        return cls(p, key, saved)

    def save_key(self, key: Key) -> None:
        """Key rotation (SETUP_SIGNING): the new key replaces the old one atomically."""
        write_atomic(self.path, format_key(key), mode=KEY_MODE)
        self.key = key

    def save_stamp(self, stamp: int) -> None:
        write_atomic(stamp_path(self.path), f"{stamp}\n", mode=KEY_MODE)
        self.saved_stamp = stamp
