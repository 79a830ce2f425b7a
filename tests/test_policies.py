"""The link-loss policies of docs/architecture.md §9 flown end to end on the same vehicle and simulator, and the paired
trials that make them comparable: each baseline shows its anchor's documented behaviour, and a trial and its baseline
are identical until the link is lost."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest

import sim
from link.radio import LinkState, Radio, RadioParams, subsystem_rng
from sim import metrics
from sim.driver import SimDriver
from sim.policies import NATIVE_POLICIES, check_policy, make_policy
from sim.policies.smartrtl import FS_TIMEOUT, SmartRTL, SmartRTLPath
from sim.runner import Run
from sim.scenario import load
from vehicle.app import DT, State

pytestmark = pytest.mark.slow

TUNNEL_S = 110.0  # the tunnel's link dies about 45 s in; a minute after is enough to see what each policy does


@functools.cache
def flown(policy: str, name: str = "tunnel", duration: float | None = TUNNEL_S, seed: int | None = None):
    r = Run(load(name), "rover", seed, duration=duration, policy=policy).run()
    r.metrics = metrics.compute(r)
    return r, r.metrics


def _k(t: float) -> int:
    """Trace index of simulated time ``t``."""
    return int(round(t / DT)) - 1


def _comms_lost(r: Run) -> float:
    return next(e.t for e in r.vehicle.event_log if e.reason.name == "COMMS_LOST")


def _variant(tmp_path: Path, base: str, replace: tuple[str, str]) -> Path:
    text = (Path(sim.__file__).parent / "scenarios" / f"{base}.toml").read_text()
    assert replace[0] in text
    path = tmp_path / f"{base}-variant.toml"
    path.write_text(text.replace(*replace))
    return path


def test_policy_names_are_checked_and_returnlink_injects_nothing():
    assert make_policy("returnlink") is None
    assert all(make_policy(p) is not None for p in NATIVE_POLICIES if p != "returnlink")
    with pytest.raises(ValueError, match="unknown policy 'bogus'"):
        check_policy("bogus")
    with pytest.raises(ValueError, match="unknown policy"):
        Run(load("tunnel"), policy="bogus")


# ----- paired trials ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("other", ["hold", "smartrtl"])
def test_a_trial_and_its_baseline_are_identical_until_the_link_is_lost(other):
    a, ma = flown("returnlink")
    b, mb = flown(other)
    lost = _comms_lost(a)
    assert _comms_lost(b) == lost
    k = _k(lost)
    # the same up to the tick the link is declared lost, where each policy acts (a return drives from it)
    assert a.trace.true[:k] == b.trace.true[:k]
    assert a.trace.link[:k + 1] == b.trace.link[:k + 1]
    assert a.trace.heard[:k + 1] == b.trace.heard[:k + 1]
    assert ma["loss_position"] == mb["loss_position"] and ma["loss_position"] is not None
    assert ma["link_lost_s"] == mb["link_lost_s"]
    # and from there only the policy differs (both operators drive home in the end, so not by where they end)
    n = min(len(a.trace.true), len(b.trace.true))
    assert max(math.dist(a.trace.true[i], b.trace.true[i]) for i in range(k, n)) > 1.0


def test_a_packets_fate_does_not_depend_on_traffic_before_it_or_the_other_direction():
    """Per-direction streams keyed by send time: extra packets (a longer plan, another direction) shift nothing."""
    state = LinkState(-85.0, -95.0, 0.5)
    ticks = [round(k * DT, 9) for k in range(1, 400)]
    quiet = Radio(RadioParams(), lambda a, b: 0.0, seed=9)
    busy = Radio(RadioParams(), lambda a, b: 0.0, seed=9)
    fates_quiet, fates_busy = [], []
    for k, t in enumerate(ticks):
        if k % 3 == 0:
            busy.packet(state, "uplink.gcs", round(t - DT / 2, 9))  # extra uplink traffic between the ticks
        busy.packet(state, "downlink.gcs", t)
        fates_quiet.append(quiet.packet(state, "uplink.gcs", t))
        fates_busy.append(busy.packet(state, "uplink.gcs", t))
    assert fates_quiet == fates_busy
    assert 0 < sum(f is None for f in fates_quiet) < len(ticks)  # a real mix of lost and delivered packets


def test_a_parameter_of_the_return_changes_nothing_before_the_loss():
    """A campaign's parameter grid pairs like its policies: RTL_SPEED and LNK_REGAIN_S act only after the loss."""
    sc = load("tunnel")
    a, ma = flown("returnlink")
    b = Run(dataclasses.replace(sc, params={**sc.params, "RTL_SPEED": 0.5, "LNK_REGAIN_S": 2.0}), "rover",
            duration=TUNNEL_S).run()
    mb = metrics.compute(b)
    k = _k(_comms_lost(a))
    assert a.trace.true[:k + 1] == b.trace.true[:k + 1]
    assert ma["loss_position"] == mb["loss_position"]
    assert mb["return_speed_mps"] < ma["return_speed_mps"]


def test_the_sensors_draw_from_their_own_stream_whatever_the_robot_draws():
    sc = load("open")
    quiet = SimDriver(sc, "legged", subsystem_rng(5, "robot"), subsystem_rng(5, "sensors"))
    busy = SimDriver(sc, "legged", subsystem_rng(5, "robot"), subsystem_rng(5, "sensors"))
    busy.robot.rng.normal(size=17)  # a different gait history: more foot-slip draws
    reads = [[d.read(k * DT, DT) for k in range(1, 200)] for d in (quiet, busy)]
    fixes = [[r.fix for r in rs if r.fix is not None] for rs in reads]
    assert fixes[0] and fixes[0] == fixes[1]


# ----- each baseline's documented behaviour -----------------------------------------------------------------------
def test_hold_stops_and_waits_where_the_link_was_lost():
    r, m = flown("hold")
    lost = _comms_lost(r)
    after = np.array(r.trace.true[_k(lost + 1.0):])  # a second to brake
    assert len(after) > 1000
    assert float(np.hypot(*(after - after[0]).T).max()) < 0.05
    assert [b["command"] for b in m["blocks"]] == ["HOLD"]
    assert m["blocks"][0]["reason"] is None  # still holding when the run ended
    assert m["regained_by"] is None and m["distance_back_m"] < 0.3


def test_rtl_heads_in_a_straight_line_for_home():
    r, m = flown("rtl")
    blk = r.blocks[0]
    home = r.scenario.start[:2]
    assert blk.command == "RTL" and len(blk.route) == 2
    assert math.dist(blk.route[-1], home) < 1e-9
    start = np.array(r.trace.true[_k(blk.started)])
    bearing = (np.array(home) - start) / math.dist(start, home)
    moved = np.array(r.trace.true[_k(blk.started + 8.0)]) - start  # the first metres of the return
    assert np.linalg.norm(moved) > 2.0
    assert float(moved @ bearing) / float(np.linalg.norm(moved)) > math.cos(math.radians(20))
    assert math.dist(r.trace.true[-1], home) < math.dist(start, home) - 20.0


def test_smartrtl_acts_fs_timeout_after_the_gcs_timeout_and_keeps_going_when_the_link_returns():
    r, m = flown("smartrtl")
    timeout = r.vehicle.params["LNK_TIMEOUT"]
    heard = r.losses[0][1]
    acted = r.vehicle.contingency.acted[0]
    assert acted - heard == pytest.approx(timeout + FS_TIMEOUT, abs=DT + 1e-9)  # SITL measured 4.55 s with 3 s
    assert m["reaction_latency_s"] == pytest.approx(FS_TIMEOUT, abs=DT + 1e-9)
    lost = _comms_lost(r)
    still = np.array(r.trace.true[_k(lost + 0.5):_k(acted)])
    assert float(np.hypot(*(still - still[0]).T).max()) < 0.05  # nothing happens until the failsafe acts
    # the link came back during the return, and SmartRTL drove on to home regardless
    regained = m["link_regained_s"]
    blk = r.blocks[0]
    assert regained is not None and blk.started < regained < blk.ended
    assert "LINK_REGAINED" not in [e["reason"] for e in m["lease_events"]]
    assert blk.reason == "COMPLETED"
    after = np.array(r.trace.true[_k(regained):_k(blk.ended)])
    assert float(np.hypot(*np.diff(after, axis=0).T).sum()) > 20.0
    assert math.dist(blk.end, r.scenario.start[:2]) < 2.0
    assert m["regained_by"] == "return"


def test_smartrtl_acts_fs_timeout_after_a_loss_on_a_marginal_link_too():
    """On `loop` the link fades (delivery under LNK_MIN_Q) while lucky packets still arrive: the lease book
    declares COMMS_LOST and takes the operator's control away, so the failsafe must act FS_TIMEOUT later rather
    than wait for a silence that never comes (it once stood still for the rest of the run)."""
    r, m = flown("smartrtl", "loop", 45.0, seed=1)
    lost = _comms_lost(r)
    assert r.vehicle.contingency.acted, "SmartRTL never acted after the loss"
    assert r.vehicle.contingency.acted[0] - lost == pytest.approx(FS_TIMEOUT, abs=DT + 1e-9)
    assert m["distance_back_m"] > 1.0


def test_smartrtl_switched_on_by_the_operator_acts_at_once(tmp_path):
    path = _variant(tmp_path, "tunnel", ("[criteria]", '[[events]]\nt = 20.0\naction = "rtl"\n\n[criteria]'))
    r = Run(load(str(path)), "rover", duration=40.0, policy="smartrtl").run()
    expired = next(e for e in r.vehicle.event_log if e.reason.name == "OPERATOR_EXPIRE")
    assert 20.0 <= expired.t < 20.5
    assert r.vehicle.contingency.acted == [pytest.approx(expired.t, abs=DT + 1e-9)]  # no failsafe delay
    assert math.dist(r.blocks[0].route[-1], r.scenario.start[:2]) < 1.0


def test_smartrtl_path_deactivates_when_full_for_its_timeout():
    path = SmartRTLPath(max_points=20, timeout=15.0)
    t, last_added = 0.0, 0.0
    # a zigzag trek (3 m either side, a corner every 4 m): simplification keeps the corners and no loop closes,
    # so the buffer fills and cleanup soon cannot make room
    while t < 600.0 and path.active:
        x = 1.0 * t
        newest = path.points[-1] if path.points else None
        path.update(x, 3.0 - abs((x % 8.0) - 4.0) * 1.5, t)
        if path.points and path.points[-1] is not newest:
            last_added = t
        t = round(t + 0.1, 9)
    assert not path.active
    assert len(path.points) == 20
    # the clock starts with the first point that finds no room (2 m after the last one), and runs 15 s
    assert 15.0 <= path.deactivated_at - last_added <= 15.0 + 2.0 / 1.0 + 0.5


def test_smartrtl_deactivated_falls_back_to_a_straight_rtl():
    r = Run(load("tunnel"), "rover", duration=TUNNEL_S, policy="smartrtl")
    # home and one point: full after a few metres; flown by the vehicle and recorded by the run, as the plant's is
    r.vehicle.contingency = r.plant.contingency = small = SmartRTL(max_points=2)
    r.run()
    assert not small.path.active and small.path.deactivated_at < _comms_lost(r)
    assert small.fallback
    blk = r.blocks[0]
    assert len(blk.route) == 2 and math.dist(blk.route[-1], r.scenario.start[:2]) < 1e-9


def test_backup_retraces_the_trail_and_stops_once_the_link_is_good():
    r, m = flown("backup")
    blk = r.blocks[0]
    assert blk.command == "BACKUP" and blk.distance > 0.5
    k0, k1 = _k(blk.started), _k(blk.ended)
    good = [k for k in range(k0, k1) if r.trace.heard[k]]
    assert good, "the link never came back during the back-up"
    assert all(r.trace.cmd[k] == (0.0, 0.0) for k in good)
    assert any(r.trace.cmd[k] != (0.0, 0.0) for k in range(k0, k1))
    assert blk.reason == "LINK_REGAINED" and m["regained_by"] == "return"
    # it backs up along the trail, not a straight line: the route is the reversed trail
    assert len(blk.route) > 3


# ----- the record of a run ----------------------------------------------------------------------------------------
def test_metrics_keys_and_block_records():
    r, m = flown("returnlink")
    assert tuple(m) == metrics.KEYS
    assert m["policy"] == "returnlink" and m["link_cycles"] == 1
    assert len(m["loss_position"]) == 2 and len(m["rest_position"]) == 2
    assert 0.0 <= m["rest_link_quality"] <= 1.0
    assert m["regained_by"] == "return" and m["collisions_during_return"] == 0
    assert m["return_speed_mps"] > 0.1
    keys = {"index", "command", "start_s", "end_s", "reason", "distance_m", "displacement_m", "limit_m"}
    assert m["blocks"] and all(set(b) == keys for b in m["blocks"])
    assert [b["command"] for b in m["blocks"]][:1] == ["RETURN_TO_LINK"]
    assert m["frames"]["loss_position"] == "true"


def test_same_seed_same_metrics_under_a_baseline():
    a = metrics.compute(Run(load("tunnel"), "rover", 4, duration=80.0, policy="backup").run())
    b = metrics.compute(Run(load("tunnel"), "rover", 4, duration=80.0, policy="backup").run())
    a.pop("real_time_factor")
    b.pop("real_time_factor")
    assert a == b


def test_a_blocks_displacement_limit_is_its_own(tmp_path):
    """Loop with RTL_MAX_DISP 5 m: the RETURN_TO_LAUNCH block has no limit, and is never judged against the
    limit of the RETURN_TO_LINK block before it."""
    path = _variant(tmp_path, "loop", ('{ command = "RETURN_TO_LINK", max_displacement = 50.0 }',
                                       '{ command = "RETURN_TO_LINK" }'))
    text = path.read_text().replace("[criteria]", "[operator.params]\nRTL_MAX_DISP = 5.0\n\n[criteria]")
    path.write_text(text)
    r = Run(load(str(path)), "rover").run()
    m = metrics.compute(r)
    by_command = {b["command"]: b for b in m["blocks"]}
    assert by_command["RETURN_TO_LINK"]["limit_m"] == 5.0
    assert by_command["RETURN_TO_LINK"]["displacement_m"] <= 5.0 + metrics.DISPLACEMENT_SLACK
    assert "RETURN_TO_LAUNCH" in by_command and by_command["RETURN_TO_LAUNCH"]["limit_m"] is None
    assert not [f for f in m["failures"] if "displacement" in f], m["failures"]


def test_a_criterion_can_require_who_regained_the_link():
    """The tunnel exists to show the return bringing the link back: held still in the adit, it fails for it."""
    assert load("tunnel").criteria.regained_by == "return"
    r, m = flown("hold")
    assert m["regained_by"] is None
    assert "link regained by None, expected by return" in m["failures"]
    r, m = flown("returnlink")
    assert m["regained_by"] == "return" and not [f for f in m["failures"] if "regained by" in f]


def test_sim_run_flies_the_policy_named_on_the_command_line(tmp_path, capsys):
    from sim.cli import main

    with pytest.raises(SystemExit) as e:
        main(["sim", "run", "tunnel", "--policy", "bogus"])
    assert e.value.code == 2 and "invalid choice: 'bogus'" in capsys.readouterr().err
    out = tmp_path / "hold"
    code = main(["sim", "run", "handover", "--policy", "hold", "--out", str(out), "--quiet"])
    m = json.loads((out / "metrics.json").read_text())
    assert m["policy"] == "hold" and [b["command"] for b in m["blocks"]] == ["HOLD"]
    assert code == (0 if m["passed"] else 1)
    assert "--policy hold" in capsys.readouterr().out


def test_baseline_path_driver_keeps_the_navigators_reverse_hysteresis():
    """A baseline drives with the navigator as the return service does, direction hysteresis included: once it
    backs up a route that lies behind, a route 90 degrees off (inside the 80-100 degree band) keeps it backing up
    instead of flipping to forward and swinging the other way round."""
    from types import SimpleNamespace

    from sim.policies.base import PathDriver
    from vehicle.params import load_defaults

    vehicle = SimpleNamespace(params=load_defaults())  # the driver reads only the vehicle's parameters
    driver = PathDriver(np.array([[0.0, 0.0], [-10.0, 0.0]]), 1.0, 0.0)
    speed, _, _ = driver.step(vehicle, 0.02, 0.0, 0.0, 0.0)  # facing north, the route runs south: back up
    assert speed < 0
    # facing west, the route 90 degrees off: it turns in place either way, but backing up it swings its tail
    # toward the route (counter-clockwise) where a flip to forward would swing its nose (clockwise)
    speed, yaw_rate, _ = driver.step(vehicle, 0.04, -0.02, 0.0, math.radians(-90.0))
    assert speed == 0.0 and yaw_rate > 0, "the direction flipped inside the hysteresis band"
    assert driver.reverse


def test_baselines_report_holding_while_they_stand_still():
    """What the operator's screen says must match what the robot does: a hold baseline reports HOLDING for its
    whole block, and SmartRTL reports HOLDING while it waits FS_TIMEOUT after COMMS_LOST, then RETURNING."""
    hold = Run(load("tunnel"), "rover", duration=TUNNEL_S, policy="hold").run()
    lost = _comms_lost(hold)
    k = int(round(lost / DT))
    assert hold.trace.state[k + 5] == State.HOLDING
    srtl = Run(load("tunnel"), "rover", duration=TUNNEL_S, policy="smartrtl").run()
    lost = _comms_lost(srtl)
    acted = srtl.vehicle.contingency.acted[0]
    waiting = srtl.trace.state[int(round(lost / DT)) + 2: int(round(acted / DT)) - 2]
    assert waiting and set(waiting) == {State.HOLDING}
    assert srtl.trace.state[int(round(acted / DT)) + 5] == State.RETURNING


def test_a_baseline_changing_state_is_announced_in_that_tick():
    """Telemetry re-reads the lease status only when something it depends on changed: SmartRTL going from its
    FS_TIMEOUT wait (HOLDING) to the retrace (RETURNING) changes no lease, so the telemetry must still see it, or
    CURRENT_MODE would show the old mode until the link came back."""
    r = Run(load("tunnel"), "rover", duration=TUNNEL_S, policy="smartrtl")
    tel = r.plant.endpoint.telemetry
    seen = set()
    for _ in range(int(round(TUNNEL_S / DT))):
        r.step()
        state = r.vehicle.state()
        seen.add(state)
        assert tel.last_status_key[-1] == state and tel.last_mode == tel.custom_mode(), r.t
    assert {State.HOLDING, State.RETURNING} <= seen


def test_a_return_drives_from_the_tick_its_lease_becomes_current_as_a_baseline_does():
    """The return service plans its route and drives it in the same tick, as back-up does: a return that drove
    only from the next tick started 20 ms behind, and at the sharp edge of a wall's radio shadow that is a
    telemetry packet heard or the next one 0.25 s later (gen:mine legged seed 118: 5.44 s to link, back-up
    5.16)."""
    for policy in ("returnlink", "backup"):
        r, _ = flown(policy)
        k = r.trace.state.index(State.RETURNING)  # the first tick the return holds the lease
        assert r.trace.cmd[k - 1] == (0.0, 0.0), policy  # stood still, the link silent, until then
        assert r.trace.cmd[k][0] != 0.0, f"{policy}: the return's first tick commanded {r.trace.cmd[k]}"
