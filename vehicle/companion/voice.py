"""What the companion says on the ground side besides its endpoint's own frames: the autopilot's frames relayed,
and answers in the autopilot's name, signed per docs/architecture.md §4.1 when a key is installed.

The autopilot signs nothing (its link to the companion is a wire), yet a ground station with the key believes only
signed frames. So with a key every frame the autopilot sends is packed again with its own header (system,
component, sequence number) and signed by the companion, as a router that terminates signing on one side does.
Without a key frames pass byte for byte. The companion's own endpoint signs its frames itself (link id 0); this
voice signs on link id 1, a stream of its own, so the two never trip each other's replay check.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as apm

from link.signing import Key, advance, enable

VOICE_LINK_ID = 1


def frame_msgid(frame: bytes) -> int | None:
    """The message id of a whole MAVLink frame, read from its header (None if it is not one)."""
    if len(frame) >= 10 and frame[0] == 0xFD:
        return frame[7] | frame[8] << 8 | frame[9] << 16
    if len(frame) >= 6 and frame[0] == 0xFE:
        return frame[5]
    return None


class GroundVoice:
    def __init__(self, key: Key | None = None, stamp: Callable[[float], int] | None = None,
                 start_stamp: int = 0) -> None:
        """``key`` None: no signing. ``stamp(t)`` is the signing clock; ``start_stamp`` where the signing timestamp
        starts (after the last one used before a restart, from the key store)."""
        self.key = key
        self.stamp = stamp
        self.enc = apm.MAVLink(None, 0, 0)
        self.seqs: dict[tuple[int, int], int] = {}  # our own answers' sequence numbers, per (system, component)
        if key is not None:
            enable(self.enc, key, start_stamp, VOICE_LINK_ID)

    def tick(self, t: float) -> None:
        if self.key is not None and self.stamp is not None:
            advance(self.enc, self.stamp(t))

    def relay(self, m) -> bytes:
        """An autopilot frame as the ground gets it: its own bytes, or packed again and signed with the key (a
        message this dialect cannot pack, an unknown id, passes as it came)."""
        raw = bytes(m.get_msgbuf())
        if self.key is None or m.get_type().startswith("UNKNOWN"):
            return raw
        enc = self.enc
        enc.srcSystem, enc.srcComponent, enc.seq = m.get_srcSystem(), m.get_srcComponent(), m.get_seq()
        return bytes(m.pack(enc))

    def say(self, sysid: int, compid: int, msg) -> bytes:
        """Our own message from (``sysid``, ``compid``): an answer in the autopilot's name, or the companion's
        word before its endpoint runs."""
        enc = self.enc
        seq = self.seqs.get((sysid, compid), 0)
        self.seqs[(sysid, compid)] = (seq + 1) % 256
        enc.srcSystem, enc.srcComponent, enc.seq = sysid, compid, seq
        return bytes(msg.pack(enc))


class RangeRelay:
    """Range data to the ground at most once every ``gap`` s per sensor: the return asks for it at 10 Hz, six
    rangefinders are 60 messages a second, and a telemetry radio has better uses for its air time."""

    def __init__(self, gap: float) -> None:
        self.gap = gap
        self.relayed: dict[tuple, float] = {}  # (sysid, compid, message, sensor) -> when last relayed

    def passes(self, m, t: float) -> bool:
        """Whether this range message goes on to the ground: a sensor's first in ``gap``."""
        key = (m.get_srcSystem(), m.get_srcComponent(), m.get_type(), getattr(m, "id", 0),
               getattr(m, "orientation", 0))
        if t - self.relayed.get(key, -math.inf) < self.gap:
            return False
        if len(self.relayed) >= 1024:  # (a vehicle has a few dozen sensors: anything more is noise)
            self.relayed.clear()
        self.relayed[key] = t
        return True
