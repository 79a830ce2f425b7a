"""Command retries (docs/architecture.md §3.9): every command of the last few seconds, per sender, answered once and
only once.

A ground station resends a COMMAND_LONG until it hears the COMMAND_ACK, and a radio can deliver a copy late. If
the vehicle remembered only the last command per command id, an RTL delayed behind a newer command would look new
and expire a lease a second time. So every (sender, compid, command, parameters) seen within ``window`` seconds is
kept with its first answer; a copy gets that answer again and is never executed again, whatever came in between.

Bounded work, as SmartRTL bounds its cleanup: entries expire in arrival order from one deque (no sort, no scan of
the table), each sender keeps at most ``per_sender`` entries and the whole table at most ``total``, so a flood of
distinct commands costs amortised O(1) per command and fixed memory. Pure: time is an argument.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

Key = tuple  # (sender, compid, command, *params)


@dataclass
class Answer:
    """The first result given to a command; a retry or late copy gets the same."""

    result: int
    param2: int
    at: float


def command_key(sender: int, compid: int, command: int, params: tuple[float, ...]) -> Key:
    """What makes two command messages "the same command": sender, its component, the id and the parameters
    (rounded, so float noise from a re-encoding is not a new command; NaN and infinities compare by name)."""
    return (sender, compid, command, *[round(x, 6) if math.isfinite(x) else str(x) for x in params])


class RetryWindow:
    def __init__(self, window: float = 3.0, per_sender: int = 64, total: int = 4096) -> None:
        self.window, self.per_sender, self.total = window, per_sender, total
        self._answers: dict[Key, Answer] = {}
        self._order: deque[tuple[Key, Answer]] = deque()  # arrival order, for expiry (may hold forgotten entries)
        self._mine: dict[tuple[int, int], deque[Key]] = {}  # live keys per (sender, compid), arrival order

    def __len__(self) -> int:
        return len(self._answers)

    def seen(self, key: Key, t: float) -> Answer | None:
        """The first answer to this very command if it came within the window, else None."""
        self._expire(t)
        return self._answers.get(key)

    def remember(self, key: Key, result: int, param2: int, t: float) -> None:
        """Record the answer to a command just executed."""
        self._expire(t)
        if key in self._answers:
            return
        mine = self._mine.setdefault((key[0], key[1]), deque())
        if len(mine) >= self.per_sender:  # one sender cannot push the others out
            self._forget(mine[0])
        while self._order and len(self._answers) >= self.total:
            self._pop_oldest()
        if len(self._order) >= 2 * self.total:
            # entries forgotten by a sender's cap are still queued: drop them (at most once per ``total`` commands,
            # a bounded filter, never a sort)
            self._order = deque(e for e in self._order if self._answers.get(e[0]) is e[1])
        answer = Answer(result, param2, t)
        self._answers[key] = answer
        self._order.append((key, answer))
        self._mine.setdefault((key[0], key[1]), mine).append(key)

    def _expire(self, t: float) -> None:
        order = self._order
        while order and t - order[0][1].at > self.window:
            self._pop_oldest()

    def _pop_oldest(self) -> None:
        key, answer = self._order.popleft()
        if self._answers.get(key) is answer:
            self._forget(key)

    def _forget(self, key: Key) -> None:
        """Drop one live entry; it is always its sender's oldest (entries leave in arrival order)."""
        del self._answers[key]
        who = (key[0], key[1])
        mine = self._mine[who]
        mine.popleft()
        if not mine:
            del self._mine[who]
