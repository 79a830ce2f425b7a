"""The command retry window (docs/architecture.md §3.9): every command of the last 3 s per sender, answered once."""

from __future__ import annotations

import math

from vehicle.retries import RetryWindow, command_key

RTL, MODE = 20, 176


def key(command: int, *params: float, sender: int = 255, compid: int = 190):
    return command_key(sender, compid, command, tuple(params) + (0.0,) * (7 - len(params)))


def test_a_late_copy_is_recognised_after_a_newer_command_with_the_same_id():
    w = RetryWindow(3.0)
    rtl, hold = key(MODE, 1, 4, 5), key(MODE, 1, 4, 3)
    w.remember(rtl, 0, 0, 10.0)
    w.remember(hold, 0, 0, 10.5)  # newer command, same command id
    assert w.seen(rtl, 11.0).result == 0  # the late RTL: answered as before, not new
    assert w.seen(hold, 11.0) is not None


def test_entries_expire_after_the_window_in_arrival_order():
    w = RetryWindow(3.0)
    w.remember(key(RTL), 0, 0, 0.0)
    w.remember(key(MODE, 1, 4, 3), 4, 0, 2.0)
    assert w.seen(key(RTL), 3.0) is not None
    assert w.seen(key(RTL), 3.01) is None and len(w) == 1
    assert w.seen(key(MODE, 1, 4, 3), 5.0).result == 4
    assert w.seen(key(MODE, 1, 4, 3), 5.1) is None and len(w) == 0


def test_the_key_is_sender_compid_command_and_parameters():
    w = RetryWindow(3.0)
    w.remember(key(RTL), 0, 0, 0.0)
    assert w.seen(key(RTL, sender=254), 0.1) is None
    assert w.seen(key(RTL, compid=191), 0.1) is None
    assert w.seen(key(RTL, 1), 0.1) is None
    assert w.seen(key(RTL, 0.0000001), 0.1) is not None  # float noise is the same command
    nan = key(RTL, math.nan)
    w.remember(nan, 4, 0, 0.2)
    assert w.seen(key(RTL, math.nan), 0.3).result == 4


def test_one_sender_flooding_neither_grows_memory_nor_pushes_others_out():
    w = RetryWindow(3.0, per_sender=64, total=256)
    w.remember(key(RTL), 0, 7, 0.0)
    for n in range(10_000):
        w.remember(key(MODE, n, sender=9), 0, 0, 0.001 * n / 10_000)
    assert len(w) <= 64 + 1
    assert w.seen(key(RTL), 0.5).param2 == 7
    assert len(w._order) <= 2 * 256 and sum(len(q) for q in w._mine.values()) == len(w)
    for n in range(1000):  # many senders: the whole table stays bounded
        w.remember(key(RTL, sender=n % 250 + 1, compid=n), 0, 0, 1.0)
    assert len(w) <= 256 and len(w._order) <= 2 * 256
    assert sum(len(q) for q in w._mine.values()) == len(w)
