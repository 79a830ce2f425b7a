"""MAVLink 2 message signing (docs/architecture.md §4.1), pure and shared by the vehicle and the ground station.

Without signing, one UDP packet is enough to learn the epoch and the owner from the broadcast telemetry and to act
as the owner: force a return, change a parameter, take the root, or keep the link-loss trigger from ever firing
with forged heartbeats. A signed frame carries a 13-byte block after its CRC: link id (1 byte), a 48-bit timestamp
in 10 µs units since 2015-01-01 00:00 UTC, and the first 48 bits of SHA-256(secret key + header + payload + CRC +
link id + timestamp). A receiver accepts it when the signature matches and, per (sysid, compid, link id) stream,
the timestamp is newer than the last accepted one (so a captured frame cannot be replayed); a stream it has never
seen must not be more than 60 s behind its own clock (so an old capture cannot open a "new" stream).

Why not pymavlink's own check: ``MAVLink.check_signature`` records the stream's timestamp *before* it compares the
signature, so a single forged frame claiming a far-future timestamp would make every genuine frame of that stream
a "replay" and lock the owner out. Here a frame whose signature does not verify never moves any timestamp.
Outgoing frames are signed by pymavlink itself (``MAVLink.signing``): ``enable`` and ``advance`` only set it up.

``Streams.verify`` is a pure function of (streams, key, frame bytes, own timestamp) returning new streams and a
``SigningVerdict``: the caller decides what a verdict means (the vehicle's gate, the station's filter).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import struct
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

from link.wire import HEADER_V2, IFLAG_SIGNED, SIGNATURE_BLOCK, STX_V2

EPOCH_UNIX = 1420070400  # 2015-01-01 00:00:00 UTC, the origin of signing timestamps
UNITS_PER_SECOND = 100_000  # timestamps count 10 µs units
NEW_STREAM_WINDOW = 6_000_000  # a new stream may be at most 60 s behind our own timestamp
MAX_TIMESTAMP = 2**48 - 1
KEY_BYTES = 32
# lockstep simulation: stamps are simulated time on top of a fixed origin (2026-01-01 UTC), so runs are repeatable
SIM_ORIGIN = (1767225600 - EPOCH_UNIX) * UNITS_PER_SECOND


class SigningVerdict(Enum):
    """What a received frame is, as far as signing goes (the lease rules' own ``Verdict`` is another thing)."""

    ACCEPT = "accepted"  # signed with the key, newer than its stream's last frame
    UNSIGNED = "unsigned"  # no signature block (or MAVLink 1)
    BAD_SIGNATURE = "wrongly signed"  # a signature block that the key does not produce: forged or another key
    REPLAY = "replayed"  # correctly signed but not newer than the last accepted frame of its stream
    TOO_OLD = "too old"  # correctly signed, a stream never seen, more than 60 s behind our clock


StreamId = tuple[int, int, int]  # (sysid, compid, link id) of the sender


def stamp_from_unix(unix_seconds: float) -> int:
    """A signing timestamp from a Unix time: 10 µs units since 2015-01-01 UTC (0 for a clock before that)."""
    return max(0, int((unix_seconds - EPOCH_UNIX) * UNITS_PER_SECOND))


def sim_stamp(t: float) -> int:
    """The signing clock of the lockstep simulator: simulated seconds on a fixed origin."""
    return SIM_ORIGIN + round(t * UNITS_PER_SECOND)


# ----- keys ----------------------------------------------------------------------------------------------------
class KeyFileError(ValueError):
    """A key file is missing, unreadable or damaged: ``path:line: what`` (or ``path: what``)."""

    def __init__(self, path: str | os.PathLike, line: int | None, what: str) -> None:
        self.path, self.line, self.what = str(path), line, what
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {what}")


@dataclass(frozen=True, repr=False)
class Key:
    """A 32-byte signing secret. Its repr shows a fingerprint only, so it never lands in a log."""

    secret: bytes

    def __post_init__(self) -> None:
        if not isinstance(self.secret, bytes) or len(self.secret) != KEY_BYTES:
            raise ValueError(f"a signing key is {KEY_BYTES} bytes")

    @classmethod
    def generate(cls) -> Key:
        return cls(os.urandom(KEY_BYTES))

    @classmethod
    def from_passphrase(cls, passphrase: str) -> Key:
        """SHA-256 of the passphrase: the key MAVProxy's ``signing key PASSPHRASE`` (and ArduPilot's tools) use."""
        return cls(hashlib.sha256(passphrase.encode("utf-8")).digest())

    def hex(self) -> str:
        return self.secret.hex()

    @property
    def fingerprint(self) -> str:
        return hashlib.sha256(b"returnlink key id" + self.secret).hexdigest()[:8]

    def __repr__(self) -> str:
        return f"Key(fingerprint={self.fingerprint})"


def parse_key(text: str, path: str | os.PathLike = "<key>") -> Key:
    """A key file's text: one line of 64 hexadecimal characters. Errors name the file and the line."""
    lines = text.splitlines()
    if not lines or not text.strip():
        raise KeyFileError(path, 1, "empty: expected one line of 64 hexadecimal characters (32 bytes)")
    first = lines[0].strip()
    if len(first) != 2 * KEY_BYTES:
        raise KeyFileError(path, 1, f"{len(first)} characters: a key is 64 hexadecimal characters (32 bytes)")
    try:
        secret = bytes.fromhex(first)
    except ValueError:
        raise KeyFileError(path, 1, "not hexadecimal: a key is 64 characters 0-9, a-f") from None
    for n, extra in enumerate(lines[1:], start=2):
        if extra.strip():
            raise KeyFileError(path, n, "unexpected text after the key: a key file holds one line")
    return Key(secret)


def format_key(key: Key) -> str:
    return key.hex() + "\n"


def load_key(path: str | os.PathLike) -> Key:
    """Read a key file (either end of the link); KeyFileError names the file and line."""
    try:
        text = Path(path).read_text(encoding="ascii")
    except UnicodeDecodeError:
        raise KeyFileError(path, 1, "not text: a key is 64 hexadecimal characters") from None
    except OSError as e:
        raise KeyFileError(path, None, e.strerror or str(e)) from None
    return parse_key(text, path)


# ----- frames --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SignatureBlock:
    stream: StreamId
    timestamp: int
    signature: bytes


def signature_block(frame: bytes) -> SignatureBlock | None:
    """The signature block of a whole MAVLink 2 frame, or None if it carries none."""
    if len(frame) < HEADER_V2 + 2 + SIGNATURE_BLOCK or frame[0] != STX_V2 or not frame[2] & IFLAG_SIGNED:
        return None
    if len(frame) != HEADER_V2 + frame[1] + 2 + SIGNATURE_BLOCK:
        return None
    link_id = frame[-13]
    timestamp = int.from_bytes(frame[-12:-6], "little")
    return SignatureBlock((frame[5], frame[6], link_id), timestamp, bytes(frame[-6:]))


def signature(key: Key, signed_part: bytes) -> bytes:
    """First 48 bits of SHA-256(key + header + payload + CRC + link id + timestamp), per the signing spec."""
    return hashlib.sha256(key.secret + bytes(signed_part)).digest()[:6]


def sign_frame(key: Key, unsigned_frame: bytes, link_id: int, timestamp: int) -> bytes:
    """Sign a whole unsigned MAVLink 2 frame (tests and tools; the endpoints let pymavlink sign what they send).

    The signed flag is part of the header and so of the CRC: the frame must have been packed with it set."""
    block = struct.pack("<BQ", link_id, timestamp)[:7]
    return bytes(unsigned_frame) + block + signature(key, bytes(unsigned_frame) + block)


@dataclass(frozen=True)
class Streams:
    """The newest accepted timestamp of every signed stream heard: the replay guard. A value: ``verify`` returns a
    new one. Only frames that verify create or move an entry, so its size is bounded by honest senders."""

    last: dict[StreamId, int] = field(default_factory=dict)

    def verify(self, key: Key, frame: bytes, now: int) -> tuple[Streams, SigningVerdict]:
        """Judge one whole frame against ``key`` with ``now`` our own signing timestamp."""
        block = signature_block(frame)
        if block is None:
            return self, SigningVerdict.UNSIGNED
        if not hmac.compare_digest(signature(key, bytes(frame[:-6])), block.signature):
            return self, SigningVerdict.BAD_SIGNATURE  # never moves a timestamp: a forgery cannot lock a stream
        previous = self.last.get(block.stream)
        if previous is not None:
            if block.timestamp <= previous:
                return self, SigningVerdict.REPLAY
        elif block.timestamp + NEW_STREAM_WINDOW < now:
            return self, SigningVerdict.TOO_OLD
        return Streams({**self.last, block.stream: block.timestamp}), SigningVerdict.ACCEPT


def timestamp_of(frame: bytes) -> int | None:
    block = signature_block(frame)
    return None if block is None else block.timestamp


# ----- signing what we send (pymavlink signs; this only configures it) -----------------------------------------
def enable(mav, key: Key, timestamp: int, link_id: int = 0) -> None:
    """Make a pymavlink ``MAVLink`` object sign every frame it packs from now on, starting at ``timestamp``."""
    s = mav.signing
    s.secret_key = key.secret
    s.link_id = link_id
    s.timestamp = min(MAX_TIMESTAMP, max(int(s.timestamp or 0), timestamp))  # 48 bits on the wire
    s.sign_outgoing = True


def advance(mav, timestamp: int) -> int:
    """Keep the outgoing timestamp at least ``timestamp`` (the clock); it never goes backwards. Returns it."""
    s = mav.signing
    s.timestamp = min(MAX_TIMESTAMP, max(s.timestamp, timestamp))
    return s.timestamp
