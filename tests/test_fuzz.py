"""The checksum-aware fuzzer (tests/fuzzing.py) in the suite: 120,000 well-framed hostile frames, seeded so a
failure reproduces. ``make fuzz`` runs a longer one (tests/fuzz_main.py)."""

from __future__ import annotations

import pytest

from tests.fuzzing import MESSAGES, Fuzzer

pytestmark = pytest.mark.slow

FRAMES = 120_000
SEED = 20260522


def test_no_frame_crashes_the_vehicle_and_no_stranger_changes_its_state():
    fuzzer = Fuzzer(SEED)
    rep = fuzzer.run(FRAMES)
    assert rep.crashes == []
    assert rep.state_changes == []
    assert rep.frames >= 100_000 and rep.owner_frames >= 20_000 and rep.garbled >= 5_000
    assert set(MESSAGES) <= rep.reached, sorted(set(MESSAGES) - rep.reached)
    # the frames got past the framer and into the handlers: commands were answered, strangers refused
    c = fuzzer.pair.endpoint.counters
    assert c.commands > 10_000 and c.bad_frames > 1_000 and fuzzer.pair.vehicle.commands_rejected > 1_000


def test_the_fuzzer_notices_a_stranger_changing_state(monkeypatch):
    """The oracle itself: with the owner check removed, a non-owner's frame changes state and is reported."""
    from vehicle.app import Vehicle

    monkeypatch.setattr(Vehicle, "refuses", lambda self, sender: False)
    rep = Fuzzer(SEED).run(20_000)
    assert rep.state_changes and "changed the state" in rep.state_changes[0]
