"""Campaigns without Ray: specs and their errors, trial ids, rows, the store and resume, the summary, the report,
replay, and the `sim run` options a campaign's trials are replayed and explored with."""

from __future__ import annotations

import csv
import json
import math
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from sim.campaign import sweep
from sim.campaign.executors import SerialExecutor
from sim.campaign.spec import MAX_TRIALS, SpecError, load_spec, parse_spec
from sim.campaign.store import FLUSH_EVERY_S, FLUSH_SHARE, Store, next_flush_gap, summary
from sim.campaign.trial import Trial, run_trial, simulate, trial_id
from sim.cli import main
from tests.campaign_helpers import TUNNEL, jam_scenario, quick_row, write_spec

pytestmark = pytest.mark.slow


# ----- specs ---------------------------------------------------------------------------------------------------
def test_spec_is_the_cartesian_product_with_inclusive_seed_range(tmp_path):
    jam_scenario(tmp_path)
    spec = load_spec(write_spec(tmp_path, """
scenarios = ["tunnel", "jam.toml"]
vehicles = ["rover", "legged"]
seeds = {from = 4, to = 6}
policies = ["returnlink"]
timeout_s = 30
[params]
LNK_TIMEOUT = [2, 5.0]
RTL_MAX_DISP = [20.0]
"""))
    assert len(spec.trials) == 2 * 2 * 3 * 2 * 1
    assert {t.seed for t in spec.trials} == {4, 5, 6}
    assert {t.scenario for t in spec.trials} == {"tunnel", "jam"}
    assert {dict(t.params)["LNK_TIMEOUT"] for t in spec.trials} == {2.0, 5.0}
    assert spec.timeout_s == 30.0
    assert len({t.id for t in spec.trials}) == len(spec.trials)


def test_spec_defaults_are_each_scenarios_own_robot_and_seed():
    spec = parse_spec('scenarios = ["tunnel"]', "s.toml")
    (t,) = spec.trials
    assert (t.vehicle, t.seed, t.policy, t.params) == ("rover", 1, "returnlink", ())


@pytest.mark.parametrize("body, line, field, words", [
    ('scenarios = ["tunnel"]\n\n[params]\nLNK_TIMEOUT = [3.0]\nNOPE = [1]\n', 5, "params.NOPE", "unknown parameter"),
    ('scenarios = ["tunnel"]\n[params]\nLNK_TIMEOUT = [3.0, 0.1]\n', 3, "params.LNK_TIMEOUT", "outside 0.5..120"),
    ('scenarios = ["tunnel"]\n[params]\nRTL_TARGET = [1.5]\n', 3, "params.RTL_TARGET", "whole number"),
    ('scenarios = ["tunnel"]\npolicies = ["returnlink", "teleport"]\n', 2, "policies[1]", "unknown policy"),
    ('scenarios = ["tunnel", "missing.toml"]\n', 1, "scenarios[1]", "cannot read scenario"),
    ('scenarios = ["broken.toml"]\n', 1, "scenarios[0]", "broken.toml: name: is required"),
    ('scenarios = ["tunnel"]\nvehicles = ["tank"]\n', 2, "vehicles[0]", "rover, legged"),
    ('scenarios = ["tunnel"]\nseeds = {from = 9, to = 2}\n', 2, "seeds", "after"),
    ('scenarios = ["tunnel"]\nseeds = [1, "two"]\n', 2, "seeds[1]", "whole number"),
    (f'scenarios = ["tunnel"]\nseeds = {{from = 0, to = {MAX_TRIALS + 5}}}\n', 2, "seeds", "more than"),
    ('scenarios = ["tunnel"]\ntimeout_s = -1\n', 2, "timeout_s", "positive"),
    ('scenarios = ["tunnel"]\nseed = [1]\n', 2, "seed", "unknown field"),
    ('vehicles = ["rover"]\n', None, "scenarios", "is required"),
    ('scenarios = ["tunnel"\n', 1, "", "not valid TOML"),
    ('scenarios = ["tunnel"]\nvehicles = [\n  "rover",\n  "legged"\n  "x",\n]\n', 5, "", "not valid TOML"),
])
def test_spec_errors_name_file_line_and_field(tmp_path, body, line, field, words):
    (tmp_path / "broken.toml").write_text('description = "no name"\n')
    path = write_spec(tmp_path, body)
    with pytest.raises(SpecError) as e:
        load_spec(path)
    assert (e.value.file, e.value.line, e.value.field) == (str(path), line, field)
    assert words in str(e.value) and str(path) in str(e.value)


def test_sweep_with_a_bad_spec_exits_2_before_any_trial(tmp_path, capsys):
    out = tmp_path / "out"
    spec = write_spec(tmp_path, 'scenarios = ["tunnel"]\npolicies = ["nope"]\n')
    assert main(["sim", "sweep", str(spec), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{spec}:2: policies[0]: unknown policy" in err and "Traceback" not in err
    assert not out.exists()
    assert main(["sim", "sweep", str(tmp_path / "none.toml"), "--out", str(out)]) == 2
    assert main(["sim", "sweep", str(spec), "--workers", "0"]) == 2
    assert main(["sim", "sweep", str(spec), "--address", "nowhere"]) == 2
    assert not out.exists()


# ----- trial ids -----------------------------------------------------------------------------------------------
def test_trial_id_is_stable_across_versions_and_processes():
    # a literal: ids are stored in campaign files and typed by people, so the hash must never drift
    assert trial_id("name = 'x'\n", "rover", 7, {"LNK_TIMEOUT": 2.0}, "returnlink") == "0aa701756fd2ad3f"
    a = trial_id("name = 'x'\n", "rover", 7, {"LNK_TIMEOUT": 2.0, "RTL_SPEED": 1.0}, "returnlink")
    assert a == trial_id("name = 'x'\n", "rover", 7, {"RTL_SPEED": 1, "LNK_TIMEOUT": 2}, "returnlink")
    assert len(a) == 16 and int(a, 16) >= 0


def test_trial_id_changes_with_every_input():
    base = dict(scenario_text="name = 'x'\n", vehicle="rover", seed=7, params={"LNK_TIMEOUT": 2.0},
                policy="returnlink")
    ref = trial_id(**base)
    for change in ({"scenario_text": "name = 'y'\n"}, {"vehicle": "legged"}, {"seed": 8},
                   {"params": {"LNK_TIMEOUT": 2.5}}, {"params": {"LNK_TIMEOUT": 2.0, "RTL_SPEED": 1.0}},
                   {"params": {}}, {"policy": "hold"}):
        assert trial_id(**{**base, **change}) != ref, change


def test_trial_id_follows_the_scenario_content_not_its_file_name(tmp_path):
    a, b = jam_scenario(tmp_path, "jam"), tmp_path / "renamed.toml"
    b.write_text(a.read_text())
    ta = parse_spec(f'scenarios = ["{a}"]', "s.toml").trials[0]
    tb = parse_spec(f'scenarios = ["{b}"]', "s.toml").trials[0]
    assert ta.id == tb.id and ta.source != tb.source


# ----- one trial, replay -----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def jam_campaign(tmp_path_factory):
    """One real trial of the jam scenario with LNK_TIMEOUT 2, run on the serial executor into a campaign dir."""
    tmp = tmp_path_factory.mktemp("camp")
    jam_scenario(tmp)
    spec = load_spec(write_spec(tmp, 'scenarios = ["jam.toml"]\nseeds = [3]\n[params]\nLNK_TIMEOUT = [2.0]\n'))
    with SerialExecutor() as ex:
        store = sweep.run_sweep(spec, Store(tmp / "out"), ex, progress=False)
    return tmp / "out", spec.trials[0], store


def test_a_trial_row_holds_inputs_every_metric_and_status(jam_campaign):
    out, trial, _ = jam_campaign
    (row,) = pq.read_table(out / "trials.parquet").to_pylist()
    assert row["trial_id"] == trial.id and row["status"] in ("ok", "failed") and row["error"] is None
    assert (row["scenario"], row["vehicle"], row["seed"], row["policy"]) == ("jam", "rover", 3, "returnlink")
    assert json.loads(row["params"]) == {"LNK_TIMEOUT": 2.0}
    assert row["link_lost_s"] is not None and row["link_regained_s"] is not None
    # the trial flew with its parameter value: the return began LNK_TIMEOUT after the owner was last heard
    assert row["return_started_s"] - row["link_lost_s"] == pytest.approx(2.0, abs=0.1)
    events = json.loads(row["lease_events"])
    assert [e["reason"] for e in events][:2] == ["NONE", "COMMS_LOST"]
    assert (row["status"] == "ok") == row["passed"]


def test_replay_reproduces_the_stored_metrics_exactly(jam_campaign, tmp_path, capsys):
    out, trial, store = jam_campaign
    rc = main(["sim", "run", "--replay", str(out), trial.id[:8], "--out", str(tmp_path / "r"), "--quiet"])
    assert rc == (0 if store.rows[trial.id]["passed"] else 1)
    assert "metrics identical to the stored trial" in capsys.readouterr().out
    m = json.loads((tmp_path / "r" / "metrics.json").read_text())
    row = store.rows[trial.id]
    for k in ("link_lost_s", "link_regained_s", "distance_back_m", "estimator_rmse_m", "trail_points"):
        assert m[k] == row[k], k
    assert (tmp_path / "r" / "trajectory.png").is_file() and (tmp_path / "r" / "timeline.png").is_file()


def test_replay_notices_a_stored_row_that_does_not_match(jam_campaign, tmp_path, capsys):
    out, trial, store = jam_campaign
    forged = Store(tmp_path)
    forged.rows = {trial.id: {**store.rows[trial.id], "distance_back_m": 123.0}}
    forged.flush()
    rc = main(["sim", "run", "--replay", str(tmp_path), trial.id, "--no-plots", "--quiet",
               "--out", str(tmp_path / "r")])
    assert rc == 1
    assert "differs from the stored trial in distance_back_m" in capsys.readouterr().err
    assert not (tmp_path / "r" / "trajectory.png").exists()


def test_replay_bad_arguments_exit_2(jam_campaign, tmp_path, capsys):
    out, trial, _ = jam_campaign
    assert main(["sim", "run", "--replay", str(out), "nosuchtrial"]) == 2
    assert main(["sim", "run", "--replay", str(tmp_path), trial.id]) == 2
    assert main(["sim", "run", "tunnel", "--replay", str(out), trial.id]) == 2
    (tmp_path / "trials.parquet").write_text("not parquet\n")
    assert main(["sim", "run", "--replay", str(tmp_path), trial.id]) == 2
    err = capsys.readouterr().err
    assert "no trial 'nosuchtrial'" in err and "not a readable parquet file" in err and "Traceback" not in err


def test_simulate_is_deterministic():
    trial = Trial("tunnel", "tunnel.toml", TUNNEL.replace("duration = 200.0", "duration = 6.0"), "legged", 5)
    a, b = simulate(trial).metrics, simulate(trial).metrics
    a.pop("real_time_factor"), b.pop("real_time_factor")
    assert a == b


# ----- store, resume, errors -----------------------------------------------------------------------------------
def fake_trials(tmp: Path, n: int = 3) -> list[Trial]:
    return [Trial("fake", "fake.toml", "name = 'fake'\n", "rover", s) for s in range(n)]


def test_a_raising_trial_is_an_error_row_and_the_sweep_goes_on():
    trials = fake_trials(Path("."))

    def flaky(t):
        if t.seed == 1:
            raise RuntimeError("the simulator fell over")
        return quick_row(t)

    rows = list(SerialExecutor().map(trials, 10.0, flaky))
    assert [r["status"] for r in rows] == ["ok", "error", "ok"]
    assert rows[1]["error"] == "RuntimeError: the simulator fell over"
    assert rows[1]["trial_id"] == trials[1].id


def test_a_policy_run_cannot_fly_is_an_error_row_not_a_crash(monkeypatch):
    import sim.campaign.trial as trial_mod

    def refuse(*_a, **_k):
        raise ValueError("policy 'hold' cannot be flown yet")

    monkeypatch.setattr(trial_mod, "simulate", refuse)
    row = run_trial(Trial("tunnel", "tunnel.toml", TUNNEL, "rover", 1, (), "hold"))
    assert row["status"] == "error" and "cannot be flown" in row["error"] and row["policy"] == "hold"


def test_a_trial_past_its_timeout_is_an_error_row():
    def slow(t):
        time.sleep(30)
        return quick_row(t)

    (row,) = SerialExecutor().map(fake_trials(Path("."), 1), 0.2, slow)
    assert row["status"] == "error" and row["error"] == "timed out after 0.2 s (wall clock)"


def test_resume_skips_finished_trials_and_reruns_error_rows_only(tmp_path):
    trials = fake_trials(tmp_path, 4)
    from sim.campaign.spec import Spec

    spec = Spec("fake.toml", tuple(trials), 10.0)
    ran: list[int] = []

    def first(t):
        ran.append(t.seed)
        if t.seed == 2:
            raise OSError("disk full")
        return {**quick_row(t), "status": "failed" if t.seed == 3 else "ok", "passed": t.seed != 3}

    sweep.run_sweep(spec, Store(tmp_path), SerialExecutor(), first, progress=False)
    assert ran == [0, 1, 2, 3]
    ran.clear()
    store = sweep.run_sweep(spec, Store(tmp_path), SerialExecutor(), lambda t: (ran.append(t.seed), quick_row(t))[1],
                            progress=False)
    assert ran == [2]  # the error row only; ok and failed rows are finished
    statuses = {r["seed"]: r["status"] for r in pq.read_table(tmp_path / "trials.parquet").to_pylist()}
    assert statuses == {0: "ok", 1: "ok", 2: "ok", 3: "failed"}
    assert len(store.rows) == 4


def test_a_damaged_trials_file_is_reported_never_replaced(tmp_path, capsys):
    jam_scenario(tmp_path)
    spec = write_spec(tmp_path, 'scenarios = ["jam.toml"]\n')
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "trials.parquet").write_bytes(b"PAR1 truncated")
    assert main(["sim", "sweep", str(spec), "--out", str(tmp_path / "out")]) == 2
    assert "trials.parquet" in capsys.readouterr().err
    assert (tmp_path / "out" / "trials.parquet").read_bytes() == b"PAR1 truncated"


# ----- summary and report ----------------------------------------------------------------------------------------
def row(seed, status="ok", policy="returnlink", lost=10.0, back=15.0, **kw):
    t = Trial("tunnel", "tunnel.toml", "x", "rover", seed, (), policy)
    return {**quick_row(t), "status": status, "link_lost_s": lost, "link_regained_s": back, **kw}


def test_summary_rates_percentiles_and_distances():
    rows = [row(0, back=12.0, distance_back_m=4.0, loss_position=[0, 0], rest_position=[3, 4],
                collisions_during_return=0),
            row(1, back=20.0, distance_back_m=6.0, loss_position="[0, 0]", rest_position="[0, 1]",
                collisions_during_return=2),
            row(2, status="failed", back=None, distance_back_m=8.0),
            row(3, status="error", lost=None, back=None),
            row(4, policy="hold", back=None, distance_back_m=0.0)]
    by = {r["policy"]: r for r in summary(rows)}
    s = by["returnlink"]
    assert (s["n"], s["ok"], s["failed"], s["errors"]) == (4, 2, 1, 1)
    assert s["pass_rate"] == pytest.approx(2 / 3) and s["link_regained_rate"] == pytest.approx(2 / 3)
    # times to link 2, 10, never: the median is 10 s and the tail says "never", not a made-up number
    assert s["time_to_link_p50_s"] == 10.0 and math.isinf(s["time_to_link_p90_s"])
    assert s["distance_back_m_mean"] == pytest.approx(6.0)
    assert s["rest_from_loss_m_mean"] == pytest.approx(3.0)
    assert s["collisions_during_return"] == 2
    h = by["hold"]
    assert h["link_regained_rate"] == 0 and h["rest_from_loss_m_mean"] is None
    assert h["collisions_during_return"] is None  # the metric is absent, not zero


def test_summary_csv_and_report_are_written(jam_campaign):
    out, trial, _ = jam_campaign
    lines = list(csv.DictReader((out / "summary.csv").open()))
    assert len(lines) == 1 and lines[0]["scenario"] == "jam" and lines[0]["n"] == "1"
    report = (out / "report.md").read_text()
    assert f"returnlink sim run --replay {out} {trial.id}" in report
    assert '| jam | rover | returnlink | {"LNK_TIMEOUT": 2.0} | 1 |' in report  # each swept value its own line
    for png in ("time_to_link_cdf.png", "distance_cdf.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG"


# ----- sim run options -------------------------------------------------------------------------------------------
def test_sim_run_param_and_plan_change_the_run(tmp_path, capsys):
    jam = jam_scenario(tmp_path)
    assert main(["sim", "run", str(jam), "--param", "LNK_TIMEOUT=1", "--plan", "loiter:20", "--no-plots",
                 "--quiet", "--out", str(tmp_path / "a")]) in (0, 1)
    m = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert m["return_started_s"] - m["link_lost_s"] == pytest.approx(1.0, abs=0.1)
    assert m["distance_back_m"] < 0.5  # a loiter plan holds still instead of driving back
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["linkmap.csv", "metrics.json", "run.tlog"]
    capsys.readouterr()


@pytest.mark.parametrize("args, words", [
    (["--param", "NOPE=1"], "NOPE: unknown parameter"),
    (["--param", "LNK_TIMEOUT=500"], "outside 0.5..120"),
    (["--param", "LNK_TIMEOUT"], "is not NAME=VALUE"),
    (["--param", "LNK_TIMEOUT=fast"], "is not a number"),
    (["--plan", "rtl:50 | fly:3"], "expected rtl"),
    (["--plan", "loiter:99999"], "outside 0..3600"),
])
def test_sim_run_bad_param_or_plan_exits_2(args, words, capsys):
    with pytest.raises(SystemExit) as e:
        main(["sim", "run", "tunnel", *args])
    assert e.value.code == 2
    assert words in capsys.readouterr().err


def test_rows_store_nested_metrics_as_json_text(tmp_path):
    store = Store(tmp_path)
    store.add(row(0, link_cycles=2.0, blocks=[{"index": 2, "reason": "COMPLETED"}], loss_position=(1.5, -2.0)))
    store.flush()
    (back,) = pq.read_table(tmp_path / "trials.parquet").to_pylist()
    assert back["link_cycles"] == 2 and json.loads(back["blocks"]) == [{"index": 2, "reason": "COMPLETED"}]
    assert json.loads(back["loss_position"]) == [1.5, -2.0]


def test_sweep_into_a_finished_campaign_runs_nothing_and_rewrites_the_report(jam_campaign, capsys):
    out, trial, _ = jam_campaign
    (out / "report.md").unlink()
    before = pq.read_table(out / "trials.parquet").to_pylist()
    assert main(["sim", "sweep", str(out.parent / "spec.toml"), "--out", str(out), "--quiet"]) == 0
    assert "all 1 trials of" in capsys.readouterr().err
    assert pq.read_table(out / "trials.parquet").to_pylist() == before
    assert trial.id in (out / "report.md").read_text()


def test_the_trials_file_is_rewritten_less_often_as_it_grows(tmp_path, monkeypatch):
    """A rewrite that took 1 s (a large campaign) is not repeated for FLUSH_SHARE seconds; a cheap one every
    FLUSH_EVERY_S: rewriting the whole file on a fixed gap would make a long campaign's bookkeeping quadratic."""
    from sim.campaign import store as store_module

    now = [0.0]
    slow = [0.0]  # what a rewrite costs on the fake clock
    real_write = store_module.write_atomic

    def write(path, data):
        now[0] += slow[0]
        real_write(path, data)

    monkeypatch.setattr(store_module, "write_atomic", write)
    store = Store(tmp_path, clock=lambda: now[0])
    store.add(row(0))
    assert not (tmp_path / "trials.parquet").exists()  # nothing due yet
    now[0] = FLUSH_EVERY_S
    slow[0] = 1.0
    store.add(row(1))  # due: written, and it took 1 s
    assert len(pq.read_table(tmp_path / "trials.parquet")) == 2
    now[0] += FLUSH_EVERY_S
    store.add(row(2))
    assert len(pq.read_table(tmp_path / "trials.parquet")) == 2  # the fixed gap is not enough any more
    now[0] += FLUSH_SHARE * 1.0 - FLUSH_EVERY_S
    store.add(row(3))
    assert len(pq.read_table(tmp_path / "trials.parquet")) == 4
    assert next_flush_gap(0.01) == FLUSH_EVERY_S
