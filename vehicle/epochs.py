"""Boot epochs of a real-time vehicle (docs/architecture.md §3.1): random at every boot, never one a delayed command may
carry.

A command carries the epoch of the root it was sent under, and the lease book rejects every other epoch
(WRONG_EPOCH). That guard only holds across a restart if the new life does not issue an epoch the old one used: a
LEASE_CLAIM delayed in a radio queue across a reboot would otherwise be executed. Deriving the epoch from a fixed
seed makes every boot issue the same one, so a real-time vehicle draws its first epoch from the operating system's
random source and keeps a small file of the epochs its recent boots issued (``FIRST LAST`` per boot), drawing again
while the new boot's range would come near one of them. Only the lockstep simulator derives its epoch from the seed,
so that its runs repeat.

The file is written with ``link.storage.write_atomic`` each time an epoch is issued (before its ACK leaves) and
read strictly: a damaged file is a ``StoredFileError`` naming the line, and the vehicle does not start on it.
"""

from __future__ import annotations

import secrets
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from link.storage import StoredFileError, read_text, remove_leftovers, write_atomic

SPACE = 0xFFFF  # epochs are 1..65535 and count up, 65535 wrapping to 1 (0 means "none" on the wire)
HEADROOM = 1024  # epochs one boot may issue (acquisitions) before its range could near an earlier boot's
KEEP = 8  # boots remembered: their ranges plus headroom cover at most an eighth of the space
TRIES = 64  # random draws before falling back to counting on from the newest range
HEADER = "# returnlink epochs issued by recent boots: FIRST LAST (docs/architecture.md §3.1)"
LEGACY_HEADERS = ("# returnlink epochs issued by recent boots: FIRST LAST (DESIGN 3.1)",)  # files older boots wrote


@dataclass(frozen=True)
class Span:
    """The epochs one boot issued: ``first`` up to ``last``, counting up (wrapping 65535 -> 1)."""

    first: int
    last: int

    def covers(self, epoch: int) -> bool:
        return (epoch - self.first) % SPACE <= (self.last - self.first) % SPACE


def after(epoch: int) -> int:
    """The epoch that follows ``epoch`` when counting up."""
    return epoch % SPACE + 1


def clear_of(epoch: int, spans: tuple[Span, ...], headroom: int = HEADROOM) -> bool:
    """True if a boot starting at ``epoch`` can issue ``headroom`` epochs without reaching any of ``spans``."""
    return all(not s.covers(epoch) and (s.first - epoch) % SPACE >= headroom for s in spans)


def choose(spans: tuple[Span, ...], draw: Callable[[int], int] = secrets.randbelow) -> int:
    """A boot epoch clear of the recent boots' epochs. ``draw(n)`` returns 0..n-1 (the OS random source)."""
    for _ in range(TRIES):
        epoch = draw(SPACE) + 1
        if clear_of(epoch, spans):
            return epoch
    # only reachable with a hostile ``draw``: count on from the newest boot, past anything still remembered
    epoch = after(spans[-1].last) if spans else 1
    while not clear_of(epoch, spans, 1):
        epoch = after(epoch)
    return epoch


def parse(text: str, path: str | Path) -> tuple[Span, ...]:
    """The spans of an epochs file, strictly: StoredFileError(path, line, what) for anything else."""
    if not text:
        raise StoredFileError(path, 1, "empty file")
    if not text.endswith("\n"):
        raise StoredFileError(path, text.count("\n") + 1, "incomplete last line (no newline at the end of the file)")
    lines = text.split("\n")[:-1]
    if lines[0] != HEADER and lines[0] not in LEGACY_HEADERS:
        raise StoredFileError(path, 1, f"expected the header {HEADER!r}")
    spans = []
    for n, line in enumerate(lines[1:], 2):
        parts = line.split()
        if len(parts) != 2 or not all(p.isdigit() for p in parts):
            raise StoredFileError(path, n, f"expected 'FIRST LAST', got {line!r}")
        first, last = int(parts[0]), int(parts[1])
        if not (1 <= first <= SPACE and 1 <= last <= SPACE):
            raise StoredFileError(path, n, f"epoch outside 1..{SPACE}")
        spans.append(Span(first, last))
    return tuple(spans)


def format_spans(spans: tuple[Span, ...]) -> str:
    return "\n".join([HEADER, *(f"{s.first} {s.last}" for s in spans)]) + "\n"


class EpochLog:
    """The imperative shell around the file: what earlier boots issued, this boot's epoch, and each new epoch
    recorded as it is issued. ``path`` None: random boot epoch, nothing kept (in-process test vehicles)."""

    def __init__(self, path: Path | None, draw: Callable[[int], int] = secrets.randbelow) -> None:
        self.path = path
        self.earlier: tuple[Span, ...] = ()
        if path is not None:
            remove_leftovers(path)
        if path is not None and path.exists():
            self.earlier = parse(read_text(path), path)[-KEEP:]
        self.boot = choose(self.earlier, draw)
        self.mine: Span | None = None

    def issued(self, epoch: int) -> str | None:
        """Record that ``epoch`` was issued (call before anyone hears of it). Returns a problem to report, if
        the file could not be written: the epoch is in use but a restart would not know it."""
        if self.mine is None:
            self.mine = Span(epoch, epoch)
        elif not self.mine.covers(epoch):
            self.mine = replace(self.mine, last=epoch)
        else:
            return None
        if self.path is None:
            return None
        try:
            write_atomic(self.path, format_spans((*self.earlier, self.mine)[-KEEP:]))
        except OSError as e:
            return f"epoch {epoch} not saved to {self.path}: {e.strerror or e}"
        return None
