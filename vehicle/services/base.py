"""What every microservice of one MAVLink component shares: the voice it answers with, who asked, what it counts.

A service (``Service``) owns the state of one MAVLink microservice and declares what it answers: message types
with ``@handles("NAME")`` and commands with ``@command(mav.MAV_CMD_...)``. It answers through the component's
``Outbox``, never a socket: one encoder per component, because MAVLink numbers a component's frames in one
sequence and signs them with one clock, whichever service speaks. A composition (``vehicle.endpoint.Endpoint``)
parses bytes into messages, checks targets and signatures, hands each message to the service that declared it and
takes the frames out of the outbox; a service can equally be driven alone, frames in and frames out, as its tests do.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

from link import dialect
from link.mission import Origin
from link.wire import NO_INDEX
from vehicle.port import VehiclePort

mav = dialect.load()

STATUSTEXT_CHUNK = 50  # bytes of text per STATUSTEXT frame
MESSAGE_NAMES = frozenset(cls.msgname for cls in mav.mavlink_map.values())

Reply = tuple[int, int]  # a command's MAV_RESULT and its COMMAND_ACK result_param2


class Source(NamedTuple):
    """Who sent the message being handled."""

    sysid: int
    compid: int
    trusted: bool = True  # signed with the installed key, or no key is installed (docs/architecture.md §4.1)


class Outbox:
    """One component's encoder and the frames it has produced since they were last taken.

    It is the file pymavlink's encoder writes finished frames to."""

    def __init__(self, sysid: int, compid: int) -> None:
        self.frames: list[bytes] = []
        self.mav = mav.MAVLink(self, sysid, compid)
        self.statustext_id = 0

    def write(self, data: bytes) -> None:
        self.frames.append(bytes(data))

    def take(self) -> list[bytes]:
        """The frames produced since the last call, oldest first."""
        frames = self.frames
        self.frames = []
        return frames

    def send(self, name: str, **fields: Any) -> None:
        """A message by its lower-case name, as pymavlink's ``<name>_send`` takes it."""
        getattr(self.mav, f"{name}_send")(**fields)

    def statustext(self, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        """STATUSTEXT, split into 50-character chunks sharing an id when longer (MAVLink 2 chunking)."""
        raw = text.encode("utf-8", "replace")
        if len(raw) <= STATUSTEXT_CHUNK:
            self.mav.statustext_send(severity, raw)
            return
        self.statustext_id = self.statustext_id % 65535 + 1
        chunks = [raw[i:i + STATUSTEXT_CHUNK] for i in range(0, len(raw), STATUSTEXT_CHUNK)]
        for n, chunk in enumerate(chunks):
            self.mav.statustext_send(severity, chunk, id=self.statustext_id, chunk_seq=n)
        if len(raw) % STATUSTEXT_CHUNK == 0:  # a full last chunk: an empty one says the text ended
            self.mav.statustext_send(severity, b"", id=self.statustext_id, chunk_seq=len(chunks))


@dataclass
class Counters:
    """What one component counts of its input, for SYS_STATUS and for the record."""

    frames: int = 0
    bad_frames: int = 0
    wrong_target: int = 0
    commands: int = 0
    command_retries: int = 0
    unsupported: int = 0
    signing: Counter = field(default_factory=Counter)  # frames per signing verdict, with a key installed
    handler_faults: int = 0  # a message whose handling raised: reported and counted, never fatal


@dataclass(frozen=True)
class Parts:
    """What a composition's services are built from (``vehicle.endpoint.Endpoint`` hands it to its factory): the
    vehicle's port (``vehicle.port``: no service sees more of the vehicle), the component's voice and counters, the
    signing service its gate uses, and the component's settings.

    The signing service is one of the composition's services to a factory (it ticks and answers SETUP_SIGNING like
    the others); only the endpoint, which built it, uses it as the gate (``vehicle.services.signing.Signing``)."""

    vehicle: VehiclePort
    out: Outbox
    counters: Counters
    signing: Service
    sysid: int
    compid: int
    origin: Origin
    boot_t: float
    param_file: Path | None
    mav_type: int | None  # the heartbeat's MAV_TYPE (None: the robot's own)
    autopilot: int  # the heartbeat's MAV_AUTOPILOT


class Throttle:
    """At most one notice per key every ``gap`` seconds: a refused stream is announced, not echoed at 10 Hz."""

    def __init__(self, gap: float) -> None:
        self.gap = gap
        self.last: dict[Any, float] = {}

    def due(self, key: Any, t: float) -> bool:
        """Whether a notice about ``key`` may go out at ``t`` (and, if so, that it is going out now)."""
        if t - self.last.get(key, -math.inf) < self.gap:
            return False
        self.last[key] = t
        return True


MessageHandler = Callable[[Any, Any, Source, float], None]  # (service, message, source, t)
CommandHandler = Callable[[Any, tuple, Source, float], Reply]  # (service, parameters, source, t) -> reply


def handles(*kinds: str) -> Callable[[Callable], Callable]:
    """Mark a method as the handler of these message types (names as in the dialect)."""
    def mark(fn: Callable) -> Callable:
        fn._handles = kinds  # type: ignore[attr-defined]
        return fn
    return mark


def command(*ids: int) -> Callable[[Callable], Callable]:
    """Mark a method as the handler of these MAV_CMD ids (named from the dialect)."""
    def mark(fn: Callable) -> Callable:
        fn._commands = ids  # type: ignore[attr-defined]
        return fn
    return mark


class Service:
    """A MAVLink microservice: its state, the messages and commands it answers, and what it does each tick.

    ``MESSAGES`` (type name -> handler) and ``COMMANDS`` (MAV_CMD id -> handler) are collected from the
    ``@handles`` / ``@command`` marks of the class and its bases when the class is defined: each is a table a
    reader, a composition or a test can read without an instance."""

    MESSAGES: ClassVar[dict[str, MessageHandler]] = {}
    COMMANDS: ClassVar[dict[int, CommandHandler]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        messages, commands = dict(cls.MESSAGES), dict(cls.COMMANDS)
        for fn in vars(cls).values():
            for kind in getattr(fn, "_handles", ()):
                if kind not in MESSAGE_NAMES:
                    raise ValueError(f"{cls.__name__}: {kind} is not a message of the dialect")
                messages[kind] = fn
            for cid in getattr(fn, "_commands", ()):
                commands[cid] = fn
        cls.MESSAGES, cls.COMMANDS = messages, commands

    def handle(self, m: Any, src: Source, t: float) -> None:
        """One message of a type this service declared; its answers go to the outbox."""
        self.MESSAGES[m.get_type()](self, m, src, t)

    def tick(self, t: float) -> None:
        """Time-driven work (time-outs, announcements, telemetry); the base has none."""


def ticks(service: Service) -> bool:
    """Whether ``service`` has time-driven work (a composition calls only those each tick)."""
    return type(service).tick is not Service.tick


def whole(x: float) -> int | None:
    """``x`` as an int if it is a finite whole number (a command parameter meant as a count or an index)."""
    return int(x) if math.isfinite(x) and x == int(x) else None


def wire_index(i: int | None) -> int:
    """A lease index on the wire (LEASE_STATUS, LEASE_EVENT): NO_INDEX for none."""
    return NO_INDEX if i is None else i


def boot_ms(t: float, boot_t: float) -> int:
    """``time_boot_ms`` of a message sent at ``t`` by a component booted at ``boot_t`` (wraps at 32 bits)."""
    return int(max(0.0, t - boot_t) * 1000) & 0xFFFFFFFF
