"""One comparator for "the same run?" (``sim.compare``): exact for returnlink's own vehicle, within its
repeatability for a real autopilot (``sim.firmware.metrics.REPEATABILITY``), on metrics alone."""

from __future__ import annotations

import math

from sim.compare import EXACT, differing
from sim.firmware.metrics import REPEATABILITY, TOLERANCE

M = {"scenario": "tunnel", "seed": 1, "passed": True, "failures": [], "real_time_factor": 812.0,
     "return_started_s": 31.22, "rest_position": [40.0, 2.5], "collisions": 0, "estimator_rmse_m": math.nan,
     "lease_events": [{"t": 0.02, "reason": "NONE"}, {"t": 31.22, "reason": "COMMS_LOST"}],
     "firmware_modes": [{"t": 0.0, "mode": "MANUAL"}, {"t": 2.0, "mode": "GUIDED"}, {"t": 31.3, "mode": "HOLD"}]}


def test_the_same_metrics_are_the_same_run_whatever_the_wall_clock_said():
    again = {**M, "real_time_factor": 640.0, "estimator_rmse_m": math.nan}  # NaN: the same missing figure
    assert differing(M, again) == [] and differing(M, again, REPEATABILITY) == []


def test_a_native_run_must_repeat_to_the_last_bit():
    nudged = {**M, "return_started_s": 31.22 + 1e-12, "collisions": 1}
    assert differing(M, nudged) == ["collisions", "return_started_s"]
    events = [M["lease_events"][0], {**M["lease_events"][1], "t": 31.24}]
    assert differing(M, {**M, "lease_events": events}) == ["lease_events"]
    assert differing(M, {**M, "failures": ["no return"], "passed": False}) == ["failures", "passed"]


def test_an_autopilot_run_is_the_same_within_its_jitter_and_not_beyond():
    jitter = {**M, "return_started_s": 31.22 + TOLERANCE["s"] / 2, "collisions": TOLERANCE["count"],
              "rest_position": [40.0 + TOLERANCE["m"] / 2, 2.5], "failures": ["x"], "passed": False}
    assert differing(M, jitter, REPEATABILITY) == []
    moved = {**M, "return_started_s": 32.0, "rest_position": [45.0, 2.5]}
    assert differing(M, moved, REPEATABILITY) == ["rest_position", "return_started_s"]


def test_a_mode_switch_a_retry_late_is_the_same_and_another_mode_is_not():
    modes = M["firmware_modes"]
    late = [{**x, "t": x["t"] + 1.0} if i == 1 else x for i, x in enumerate(modes)]
    later = [{**x, "t": x["t"] + 2.0} if i == 1 else x for i, x in enumerate(modes)]
    other = [{**x, "mode": "HOLD"} if i == 1 else x for i, x in enumerate(modes)]
    assert differing(M, {**M, "firmware_modes": late}, REPEATABILITY) == []
    assert differing(M, {**M, "firmware_modes": later}, REPEATABILITY) == ["firmware_modes"]
    assert differing(M, {**M, "firmware_modes": other}, REPEATABILITY) == ["firmware_modes"]
    assert differing(M, {**M, "firmware_modes": modes[:-1]}, REPEATABILITY) == ["firmware_modes"]


def test_a_metric_on_one_side_only_differs():
    assert differing(M, {**M, "link_cycles": 1}) == ["link_cycles"]
    assert differing({**M, "link_regained_s": None}, M) == []  # absent and null: the same missing figure
    assert EXACT.exact and not REPEATABILITY.exact
