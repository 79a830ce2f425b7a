"""PX4 as a plant on the one simulator loop (docs/architecture.md §10.1): vehicle ``px4rover`` flying PX4's own
data-link failsafe as policies ``px4-hold`` (NAV_DLL_ACT 1) and ``px4-return`` (NAV_DLL_ACT 2). The real PX4 flies a
short tunnel with a jammed window under each policy: the link is lost, PX4's failsafe nav state shows in
``firmware_modes``, the operator takes control again once the link is back, and nothing is left running; the
command line's exit-2 cases (no PX4, a broken one, a policy the vehicle cannot fly), a PX4 that never connects
within its boot budget, and the campaign spec's pairing errors.

The real PX4 comes from $RETURNLINK_PX4, else from the shared tree beside the repository (../shared/px4); with
neither the tests that need it skip, and a variable that is set but unusable fails them (as in test_px4_bridge.py).
The tests of the command line's refusals and of the boot budget use stand-in PX4 trees and always run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sim import metrics
from sim.campaign.spec import SpecError, parse_spec
from sim.cli import main
from sim.plants.px4 import COM_OF_LOSS_T_MAX, PX4Plant, px4_params
from sim.policies import PX4_FAILSAFE_POLICIES, check_policy, flies
from sim.px4 import process
from sim.px4.locate import ENV
from sim.px4.lockstep import HOLD, OFFBOARD, RETURN, PX4Unusable, nav_state_name
from sim.px4.process import PX4Error, lock_held
from sim.runner import Run, plant_for
from sim.scenario import parse
from tests.firmware_helpers import group_gone, px4_or_skip

pytestmark = [pytest.mark.interop, pytest.mark.firmware]

ROOT = Path(__file__).resolve().parents[1]
JAM_FROM, JAM_FOR = 12.0, 14.0  # s: the operator's radio hears nothing and is heard by nobody in this window


def jammed_tunnel(duration: float = 50.0) -> str:
    """The tunnel cut to ``duration`` s, with the operator's radio jammed from JAM_FROM for JAM_FOR s: the rover is
    still in the straight drift then, so both failsafes have room, and the link comes back within the run."""
    text = (ROOT / "sim" / "scenarios" / "tunnel.toml").read_text(encoding="utf-8")
    lines = [f"duration = {duration}" if line.startswith("duration =") else line for line in text.splitlines()]
    return "\n".join(lines) + f'\n[[events]]\nt = {JAM_FROM}\naction = "jam"\nstation = "gcs"\nduration = {JAM_FOR}\n'


def fake_px4(root: Path, script: str) -> Path:
    """A PX4 tree whose bin/px4 is ``script`` (a shell script): it passes the directory checks and runs as PX4."""
    (root / "bin").mkdir(parents=True)
    (root / "etc" / "init.d-posix" / "airframes").mkdir(parents=True)
    (root / "bin" / "px4").write_text(f"#!/bin/sh\n{script}\n")
    (root / "bin" / "px4").chmod(0o755)
    (root / "etc" / "init.d-posix" / "rcS").write_text("")
    (root / "etc" / "init.d-posix" / "airframes" / "1069_hil_rover_differential").write_text("")
    return root


class Started:
    """Every PX4 a test starts, by process id and instance (PX4Process.start wrapped), to check none outlives it."""

    def __init__(self, monkeypatch) -> None:
        self.pids: list[tuple[int, int, Path]] = []
        real = process.PX4Process.start

        def start(p):
            out = real(p)
            self.pids.append((p.pid, p.instance, p.workdir))
            return out

        monkeypatch.setattr(process.PX4Process, "start", start)

    def all_gone(self) -> bool:
        return bool(self.pids) and all(group_gone(pid) and not lock_held(n) and not wd.exists()
                                       for pid, n, wd in self.pids) and not process._live


# ----- without PX4: the parameters, the policy names, the spec, the command line's refusals ----------------------
def test_each_policy_sets_its_failsafe_and_the_offboard_loss_comes_later_with_the_same_action():
    hold, ret = px4_params("px4-hold", 3.0, 1.5), px4_params("px4-return", 2.5, 1.5)
    assert (hold["NAV_DLL_ACT"], hold["COM_OBL_RC_ACT"]) == (1, 5)  # Hold, Hold
    assert (ret["NAV_DLL_ACT"], ret["COM_OBL_RC_ACT"]) == (2, 3)  # Return, Return
    assert hold["COM_DL_LOSS_T"] == 3 and ret["COM_DL_LOSS_T"] == 3  # whole seconds in PX4: rounded up
    assert hold["COM_OF_LOSS_T"] == COM_OF_LOSS_T_MAX > hold["COM_DL_LOSS_T"] + 5  # the data link's failsafe first
    assert hold["COM_FAIL_ACT_T"] == 0 and hold["RO_SPEED_LIM"] == 1.5
    for bad in (("px4-rtl", 3.0, 1.0), ("px4-hold", 0.0, 1.0), ("px4-hold", float("nan"), 1.0),
                ("px4-hold", 3.0, -1.0), ("ardupilot-hold", 3.0, 1.0)):
        with pytest.raises(ValueError):
            px4_params(*bad)


def test_only_px4rover_flies_the_px4_policies_and_it_flies_nothing_else():
    for p in PX4_FAILSAFE_POLICIES:
        assert flies(p, "px4rover") and not any(flies(p, v) for v in ("rover", "legged", "ardurover"))
        with pytest.raises(ValueError, match=f"{p}.*PX4.*vehicle 'px4rover'"):
            check_policy(p)
    for p in ("returnlink", "hold", "smartrtl", "ardupilot-hold", "ardupilot-smartrtl"):
        assert not flies(p, "px4rover")
    assert flies("companion", "px4rover") and flies("companion", "ardurover")  # beside either autopilot (§11.2)
    assert flies("ardupilot-rtl", "ardurover") and flies("returnlink", "rover")  # the others as before
    assert plant_for("px4rover", "px4-hold") is PX4Plant
    with pytest.raises(ValueError, match="policy 'ardupilot-hold'"):
        PX4Plant(parse(jammed_tunnel(), "t.toml"), policy="ardupilot-hold", px4=Path("/nonexistent"))


@pytest.mark.parametrize("vehicles, policies, field, says", [
    ('["ardurover"]', '["px4-hold"]', "policies[0]", "policy 'px4-hold' needs vehicle 'px4rover'"),
    ('["rover", "px4rover"]', '["returnlink", "ardupilot-hold"]', "policies[1]",
     "policy 'ardupilot-hold' needs vehicle 'ardurover'"),
    ('["px4rover"]', '["ardupilot-smartrtl"]', "policies[0]", "needs vehicle 'ardurover'"),
    ('["rover", "px4rover"]', '["returnlink"]', "vehicles[1]", "no listed policy can be flown by vehicle 'px4rover'"),
])
def test_a_spec_pairing_a_policy_with_a_vehicle_that_cannot_fly_it_names_file_line_and_field(vehicles, policies,
                                                                                             field, says):
    text = f'scenarios = ["tunnel"]\nvehicles = {vehicles}\nseeds = [1]\npolicies = {policies}\n'
    with pytest.raises(SpecError) as e:
        parse_spec(text, "pairs.toml")
    line = 2 if field.startswith("vehicles") else 4
    assert str(e.value).startswith(f"pairs.toml:{line}: {field}: ") and says in str(e.value)


def test_the_px4_spec_pairs_returnlink_with_the_rover_and_the_px4_failsafes_and_the_companion_with_px4():
    from sim.campaign.spec import load_spec

    spec = load_spec(ROOT / "sim" / "campaign" / "specs" / "px4.toml")
    pairs = {(t.scenario, t.vehicle, t.policy) for t in spec.trials}
    assert len(spec.trials) == 3 * 10 * 4
    assert {v for _, v, _ in pairs} == {"rover", "px4rover"}
    assert all((v == "px4rover") == (p.startswith("px4-") or p == "companion") for _, v, p in pairs)


def _exit_2(capsys, argv: list[str]) -> str:
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and "Traceback" not in err
    return err


def test_no_px4_or_a_broken_one_is_exit_2_naming_both_ways(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv(ENV, raising=False)
    out = str(tmp_path / "out")
    run = ["sim", "run", "tunnel", "--vehicle", "px4rover", "--quiet", "--no-plots", "--out", out]
    err = _exit_2(capsys, run)
    assert "--px4 DIR" in err and ENV in err
    err = _exit_2(capsys, [*run, "--px4", str(tmp_path / "nowhere")])
    assert "--px4" in err and "no executable bin/px4" in err
    monkeypatch.setenv(ENV, str(tmp_path / "nowhere"))
    assert f"{ENV}=" in _exit_2(capsys, run)
    monkeypatch.delenv(ENV)
    started = Started(monkeypatch)
    broken = fake_px4(tmp_path / "broken", "echo 'cannot execute: wrong platform'; exit 3")
    err = _exit_2(capsys, [*run, "--px4", str(broken)])
    assert "--px4 DIR" in err and ENV in err and "exited before it connected" in err and "wrong platform" in err
    assert started.all_gone()


def test_a_policy_the_vehicle_cannot_fly_is_exit_2(tmp_path, capsys):
    out = ["--quiet", "--out", str(tmp_path / "o")]
    err = _exit_2(capsys, ["sim", "run", "tunnel", "--vehicle", "px4rover", "--policy", "ardupilot-hold", *out])
    assert "px4-hold or px4-return" in err
    err = _exit_2(capsys, ["sim", "run", "tunnel", "--vehicle", "rover", "--policy", "px4-return", *out])
    assert "needs PX4" in err and "--vehicle px4rover" in err
    err = _exit_2(capsys, ["sim", "run", "tunnel", "--vehicle", "rover", "--px4", str(tmp_path), *out])
    assert "--px4 goes with --vehicle px4rover" in err


def test_a_px4_that_never_connects_fails_within_its_boot_budget_and_is_stopped(tmp_path, monkeypatch):
    started = Started(monkeypatch)
    silent = fake_px4(tmp_path / "silent", "exec sleep 600")  # runs, never connects to the simulator link
    sc = parse(jammed_tunnel(), "t.toml")
    run = Run(sc, "px4rover", 1, policy="px4-hold", px4=silent, accept_timeout_s=1.5)
    with pytest.raises(PX4Error, match="did not connect to the simulator link within 1.5 s") as e:
        run.run()
    assert not isinstance(e.value, PX4Unusable)  # running but silent: not a broken install, a failed start
    assert started.all_gone()


# ----- the real PX4 ------------------------------------------------------------------------------------------------
def _story(m: dict) -> list[str]:
    return [e["mode"] for e in m["firmware_modes"]]


def test_px4_hold_holds_after_the_link_dies_and_the_operator_drives_on_after_it_returns(monkeypatch):
    px4 = px4_or_skip()
    started = Started(monkeypatch)
    run = Run(parse(jammed_tunnel(), "jammed-tunnel.toml"), "px4rover", 1, policy="px4-hold", px4=px4).run()
    m = run.metrics = metrics.compute(run)
    assert started.all_gone()
    assert m["vehicle"] == "px4rover" and m["policy"] == "px4-hold" and m["firmware"].startswith("PX4 v")
    assert _story(m) == ["AUTO_LOITER", "OFFBOARD", "AUTO_LOITER", "OFFBOARD"], m["firmware_modes"]
    failsafe = m["firmware_modes"][2]["t"]
    # last heard just before the jam; PX4 reacts COM_DL_LOSS_T (3 s) later, plus up to its heartbeat bookkeeping
    assert JAM_FROM - 1.0 <= m["link_lost_s"] <= JAM_FROM
    assert 0.0 <= m["reaction_latency_s"] <= 3.0 and m["return_started_s"] == pytest.approx(failsafe, abs=0.05)
    assert JAM_FROM + JAM_FOR <= m["link_regained_s"] <= JAM_FROM + JAM_FOR + 3.0
    assert m["blocks"][0]["command"] == "AUTO_LOITER" and m["max_displacement_m"] < 1.5  # Hold: it stops
    assert m["final_target_error_m"] is None  # Hold has no target
    assert m["firmware_modes"][3]["t"] > m["link_regained_s"] - 1.5  # the operator's Offboard once it hears again
    assert m["collisions"] == 0 and m["estimator_rmse_m"] < 0.5
    assert m["real_time_factor"] > 2.0


def test_px4_return_drives_home_from_the_command_line_and_leaves_nothing_running(tmp_path, monkeypatch, capsys):
    px4 = px4_or_skip()
    started = Started(monkeypatch)
    scenario = tmp_path / "jammed-tunnel.toml"
    scenario.write_text(jammed_tunnel())
    out = tmp_path / "out"
    code = main(["sim", "run", str(scenario), "--vehicle", "px4rover", "--policy", "px4-return", "--px4", str(px4),
                 "--quiet", "--out", str(out)])
    printed = capsys.readouterr().out
    assert started.all_gone()
    m = json.loads((out / "metrics.json").read_text())
    assert code == (0 if m["passed"] else 1), printed
    assert (out / "trajectory.png").stat().st_size > 0 and (out / "timeline.png").stat().st_size > 0
    assert (out / "run.tlog").stat().st_size > 0 and (out / "px4.log").is_file()
    assert "AUTO_RTL" in printed and "--vehicle px4rover" in printed
    assert _story(m)[:3] == ["AUTO_LOITER", "OFFBOARD", "AUTO_RTL"] and _story(m)[-1] == "OFFBOARD", m
    assert JAM_FROM - 1.0 <= m["link_lost_s"] <= JAM_FROM and 0.0 <= m["reaction_latency_s"] <= 3.0
    # Return is a straight drive to launch: down the straight drift, home is where the rover armed (its start)
    assert m["blocks"][0]["command"] == "AUTO_RTL" and m["distance_back_m"] > 8.0
    assert m["final_target_error_m"] < 1.5 and m["regained_by"] == "return"
    assert m["collisions"] == 0


def test_the_nav_states_are_named_as_px4_names_them():
    assert (nav_state_name(OFFBOARD), nav_state_name(HOLD), nav_state_name(RETURN)) == (
        "OFFBOARD", "AUTO_LOITER", "AUTO_RTL")
    assert nav_state_name((4 << 16) | (99 << 24)) == "PX4_4_99"
