"""The one printed summary (``sim.summary``), whichever plant flew the run: the same layout for returnlink's
vehicle and a real autopilot, a "-" where the plant has no figure, the plant's own lines under the first, the lease
events or the modes where there are any, the notes, the verdict."""

from __future__ import annotations

from types import SimpleNamespace

from sim.summary import summary

BASE = {"scenario": "tunnel", "vehicle": "rover", "seed": 1, "policy": "returnlink", "sim_duration_s": 200.0,
        "real_time_factor": 300.0, "link_lost_s": 41.5, "return_started_s": 44.5, "reaction_latency_s": 0.0,
        "link_regained_s": 46.7, "distance_back_m": 1.86, "max_displacement_m": 1.86, "final_target_error_m": 1.0,
        "loss_position": [42.0, 2.1], "rest_position": [41.1, 1.4], "rest_link_quality": 1.0, "regained_by": "return",
        "link_cycles": 1, "collisions": 0, "collisions_during_return": 0, "stale_commands_executed": 0,
        "commands_rejected": 3, "estimator_rmse_m": 0.22, "trail_points": 11, "trail_max_deviation_m": 0.28,
        "lease_events": [{"t": 44.5, "expired": 1, "current": 2, "reason": "COMMS_LOST"}], "passed": True,
        "failures": []}
QUIET = SimpleNamespace(notes=[])


def test_a_native_run_says_its_leases_and_no_modes():
    text = summary(QUIET, BASE)
    lines = text.splitlines()
    assert lines[0] == "returnlink sim run tunnel --vehicle rover --seed 1 --policy returnlink"
    assert "reaction 0.000 s after the trigger's condition" in text and "trail 11 points" in text
    assert lines[-3:] == ["  lease events:", "      44.50 s  1 -> 2  COMMS_LOST", "  PASSED"]
    assert "modes" not in text and "note" not in text


def test_an_autopilot_run_has_the_same_layout_with_dashes_its_lines_its_modes_and_notes():
    m = {**BASE, "vehicle": "ardurover", "policy": "ardupilot-hold", "stale_commands_executed": None,
         "trail_points": None, "trail_max_deviation_m": None, "lease_events": [], "passed": False,
         "failures": ["no return"], "firmware_modes": [{"t": 0.0, "mode": "MANUAL"}, {"t": 44.5, "mode": "HOLD"}]}
    run = SimpleNamespace(notes=["t=50 s: event 'claim' does not apply to ArduPilot"])
    lines = summary(run, m, ["  firmware ArduRover V4.6 (booted in 3.0 simulated s before scenario time 0)"],
                    "nav states").splitlines()
    assert lines[1].startswith("  firmware ArduRover")
    assert [line.split(",")[0] for line in lines[2:8]] == [line.split(",")[0] for line in
                                                           summary(QUIET, BASE).splitlines()[1:7]]
    assert "stale commands executed -" in lines[6] and "trail - points (max deviation -)" in lines[7]
    assert lines[8:] == ["  nav states:", "       0.00 s  MANUAL", "      44.50 s  HOLD",
                         "  note: t=50 s: event 'claim' does not apply to ArduPilot", "  FAILED: no return"]
