"""The words of the lease rules (docs/architecture.md §3): identities, holders, states, reasons and answers.

Plain immutable values and no rules: the ledger (``lease_ledger``), the root rules (``lease_root``) and the
stale-command guard (``lease_guard``) all speak this vocabulary, and so do the endpoint, the telemetry and the
simulator. The book's state the rules read and return (``BookState``, with its ``LeaseConfig``) is such a value
too; ``vehicle.lease.LeaseBook`` adds the rules to it. ``Holder``, ``ExpireReason`` and the vehicle's ``State``
mirror enums of the dialect (LEASE_HOLDER, LEASE_EXPIRE_REASON, RETURNLINK_STATE); ``tests/test_dialect.py`` ties
them by name and value.

Vocabulary (patent US 2022/0197292): ``[E]`` is the root lease with epoch E, ``[E,i]`` execution lease i, and
``[E,i,j,...]`` its subleases. The *current* execution lease is the lowest-index lease that has not expired.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar

from link.parameters import default
from link.wire import NO_INDEX  # noqa: F401 - the lease vocabulary's "no lease", re-exported for its readers
from vehicle.link_watch import LinkWatch, WatchConfig

if TYPE_CHECKING:
    from vehicle.params import Params


class Holder(enum.IntEnum):
    """LEASE_HOLDER."""

    NONE = 0
    OPERATOR = 1
    RETURN_SERVICE = 2


class State:
    """RETURNLINK_STATE: what the vehicle is doing, as LEASE_STATUS reports it (the current lease's holder, and
    for a return block what its running item does). Plain ints rather than an enum: the simulator keeps one in
    every per-tick row it records, and rows of plain numbers are left alone by the garbage collector."""

    NO_OWNER = 0
    TELEOP = 1
    AWAITING_CLAIM = 2
    RETURNING = 3
    HOLDING = 4
    NAVIGATING = 5


class LeaseState(enum.IntEnum):
    SCHEDULED = 0
    CURRENT = 1
    EXPIRED = 2


class ExpireReason(enum.IntEnum):
    """LEASE_EXPIRE_REASON: the expiration triggers of docs/architecture.md §3.5."""

    NONE = 0
    COMMS_LOST = 1
    OPERATOR_EXPIRE = 2
    NEWER_LEASE = 3
    COMPLETED = 4
    LINK_REGAINED = 5
    TIMEOUT = 6
    STUCK = 7
    ROOT_REPLACED = 8
    RELEASED = 9


class Verdict(enum.Enum):
    """What enforcement decides about one command: run it now, hold it for its lease, or refuse it."""

    EXECUTE = "execute"
    QUEUE = "queue"
    REJECT = "reject"


class RejectReason(enum.Enum):
    NOT_IN_CONTROL = "not in control"
    WRONG_EPOCH = "wrong epoch"
    EXPIRED = "expired lease"
    INVALID = "invalid lease"


@dataclass(frozen=True, order=True)
class LeaseId:
    """``[E,i,j,...]``: an epoch and a path of sequence numbers (empty path = the root lease)."""

    epoch: int
    path: tuple[int, ...] = ()

    @property
    def index(self) -> int:
        """Execution-lease index i; the root has none."""
        if not self.path:
            raise ValueError(f"{self} is a root lease and has no execution index")
        return self.path[0]

    @property
    def sub(self) -> tuple[int, ...]:
        """The sublease part below the execution lease: ``(j, ...)``."""
        return self.path[1:]

    def child(self, n: int) -> LeaseId:
        return LeaseId(self.epoch, (*self.path, n))

    def is_ancestor_of(self, other: LeaseId) -> bool:
        """True for the same lease or one it was divided from."""
        return self.epoch == other.epoch and other.path[: len(self.path)] == self.path

    def newer_than(self, other: LeaseId) -> bool:
        """Within one epoch, a later sequence is newer; leases of different epochs are not ordered."""
        if self.epoch != other.epoch:
            raise ValueError(f"{self} and {other} belong to different epochs")
        return self.path > other.path

    def __str__(self) -> str:
        return "[" + ",".join(str(x) for x in (self.epoch, *self.path)) + "]"

    @classmethod
    def parse(cls, text: str) -> LeaseId:
        parts = [int(p) for p in text.strip().strip("[]").split(",") if p.strip()]
        if not parts:
            raise ValueError(f"not a lease id: {text!r}")
        return cls(parts[0], tuple(parts[1:]))


@dataclass(frozen=True)
class ServiceBlock:
    """One block of the return plan as the lease rules see it; ``payload`` is the planner's business."""

    payload: Any = None
    halt_on_regain: bool = True


@dataclass(frozen=True)
class ExecutionLease:
    index: int
    holder: Holder
    state: LeaseState
    block: ServiceBlock | None = None
    claimed: bool = True
    chain: int = 0  # leases of one scheduled return plan share a chain number
    newest_sub: tuple[int, ...] = ()  # newest sublease path issued under this lease
    started_at: float | None = None


@dataclass(frozen=True)
class QueuedCommand:
    """A command sent under a SCHEDULED lease, held until that lease becomes current."""

    lease: LeaseId
    sender: int
    payload: Any


# who holds the new current lease, in a word short enough for one STATUSTEXT
_HOLDER_WORD = {Holder.NONE: "none", Holder.OPERATOR: "operator", Holder.RETURN_SERVICE: "return"}


@dataclass(frozen=True)
class LeaseEvent:
    """Exactly one per transition: logged, journalled and sent as LEASE_EVENT + STATUSTEXT."""

    t: float
    epoch: int
    expired: int | None
    current: int | None
    reason: ExpireReason
    holder: Holder

    def describe(self) -> str:
        """The STATUSTEXT line: at most 50 characters for every epoch, index, reason and holder, so it travels in
        one STATUSTEXT without chunks (a chunked text arrives in pieces, and a lost piece garbles it)."""
        exp = "-" if self.expired is None else str(self.expired)
        cur = "-" if self.current is None else str(self.current)
        return f"lease {self.epoch}: {exp}->{cur} {self.reason.name} {_HOLDER_WORD[self.holder]}"


@dataclass(frozen=True)
class Check:
    """An enforcement verdict for one command."""

    verdict: Verdict
    lease: LeaseId | None = None
    reason: RejectReason | None = None
    detail: str = ""

    @property
    def executes(self) -> bool:
        return self.verdict is Verdict.EXECUTE


def refused(reason: RejectReason, detail: str, lease: LeaseId | None = None) -> Check:
    """A REJECT verdict: every refusal names its reason and says why in words (for the STATUSTEXT)."""
    return Check(Verdict.REJECT, lease, reason, detail)


class Outcome(NamedTuple):
    """The result of a transition: the new book, its events and any queued commands released or dropped.

    A named tuple, so a caller may unpack it (``book, events, released, dropped = out``) or read it by name, and
    ``_replace`` adds to what a transition dropped."""

    book: BookState  # the new book: of the class of the one the transition was given (a ``LeaseBook``)
    events: tuple[LeaseEvent, ...] = ()
    released: tuple[QueuedCommand, ...] = ()
    dropped: tuple[QueuedCommand, ...] = ()


@dataclass(frozen=True)
class LeaseConfig:
    """The parameters the rules depend on (LNK_*, RTL_REARM, LEASE_*); defaults from the parameter table."""

    link_timeout: float = default("LNK_TIMEOUT")
    regain_s: float = default("LNK_REGAIN_S")
    contact_gap: float = default("LNK_GOOD_S")  # the longest gap between messages that still counts as contact
    min_quality: float = default("LNK_MIN_Q")  # owner's delivery below this for link_timeout is lost too
    rearm: bool = bool(default("RTL_REARM"))
    autogrant: bool = bool(default("LEASE_AUTOGRANT"))
    stale_take: bool = bool(default("LEASE_STALE_TAKE"))

    @classmethod
    def from_params(cls, params: Params) -> LeaseConfig:
        return cls(link_timeout=params["LNK_TIMEOUT"], regain_s=params["LNK_REGAIN_S"],
                   contact_gap=params["LNK_GOOD_S"], min_quality=params["LNK_MIN_Q"],
                   rearm=bool(params["RTL_REARM"]), autogrant=bool(params["LEASE_AUTOGRANT"]),
                   stale_take=bool(params["LEASE_STALE_TAKE"]))

    @property
    def watch(self) -> WatchConfig:
        """The part of the configuration the owner's link watch works with."""
        return WatchConfig(timeout=self.link_timeout, regain_s=self.regain_s, contact_gap=self.contact_gap,
                           min_quality=self.min_quality)


@dataclass(frozen=True)
class BookState:
    """What the lease book holds, and the queries that only read it: the value every rule (``lease_guard``,
    ``lease_root``, ``lease_ledger``) takes and returns. ``vehicle.lease.LeaseBook`` is this value
    with the rules as its methods; declared here, below the rules, so that no rule imports the book that calls it."""

    config: LeaseConfig = field(default_factory=LeaseConfig)
    epoch: int | None = None
    owner: int | None = None  # MAVLink sysid of the ground station holding the root
    owner_compid: int = 0
    leases: tuple[ExecutionLease, ...] = ()  # the live sequence; expired leases are dropped after their event
    next_index: int = 0
    chains: int = 0
    plan: tuple[ServiceBlock, ...] = (ServiceBlock(),)
    claims: tuple[tuple[int, LeaseId], ...] = ()  # (sysid, last lease it claimed)
    queue: tuple[QueuedCommand, ...] = ()
    link: LinkWatch = field(default_factory=LinkWatch)  # the owner's link (kept in step with ``config``)
    last_reason: ExpireReason = ExpireReason.NONE
    takeover_allowed: bool = False
    last_epoch: int | None = None

    @property
    def current(self) -> ExecutionLease | None:
        return self.leases[0] if self.leases else None

    @property
    def current_id(self) -> LeaseId | None:
        cur = self.current
        return None if cur is None or self.epoch is None else LeaseId(self.epoch, (cur.index,))

    @property
    def scheduled(self) -> tuple[ExecutionLease, ...]:
        return self.leases[1:]

    @property
    def returning(self) -> bool:
        """A service block of the return plan holds the current lease: the return is running."""
        return bool(self.leases) and self.leases[0].holder is Holder.RETURN_SERVICE

    def lease(self, index: int) -> ExecutionLease | None:
        for lease in self.leases:
            if lease.index == index:
                return lease
        return None

    def claimed_by(self, sysid: int) -> LeaseId | None:
        for s, lid in self.claims:
            if s == sysid:
                return lid
        return None

    def link_up(self) -> bool:
        return self.owner is not None and not self.link.lost


Book = TypeVar("Book", bound=BookState)  # a rule returning the book it was given, changed: of its class (LeaseBook)
