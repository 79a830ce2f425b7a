"""The speed work changes how a tick is computed, never what it computes: the fixed runs of ``CASES``, recorded before
that work, must come out bit for bit the same: every metric but the
wall-clock real_time_factor, every true and estimated position, every command, lease state and .tlog byte."""

from __future__ import annotations

import json

import pytest

from tests.golden_runs import CASES, fingerprint, path_of

pytestmark = pytest.mark.slow


@pytest.mark.parametrize(("scenario", "vehicle", "seed", "duration"), CASES)
def test_run_matches_its_golden_fingerprint(scenario, vehicle, seed, duration):
    want = json.loads(path_of(scenario, vehicle, seed).read_text(encoding="utf-8"))
    got = json.loads(json.dumps(fingerprint(scenario, vehicle, seed, duration), sort_keys=True))
    assert got["metrics"] == want["metrics"]
    assert got["metrics"]["lease_events"] == want["metrics"]["lease_events"]
    for key in ("ticks", "true", "est", "cmd", "states", "tlog"):
        assert got[key] == want[key], key
