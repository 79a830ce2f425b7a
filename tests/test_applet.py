"""The Lua applet's Python side, without the firmware (docs/architecture.md §11.3): the policy in specs and on the
command line, the applet's parameters from a scenario's, its parameter table as documented, the record's reading
of its returns, and the scripted operator's hands off a returning rover."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import pytest

from sim.campaign.spec import SpecError, parse_spec
from sim.firmware.applet_operator import AppletOperator
from sim.firmware.operator import GUIDED, HOLD
from sim.plants.applet import MIRRORED, RETURNING, AppletPlant, applet_params
from sim.policies import APPLET_POLICY, check_policy, flies
from sim.runner import plant_for
from sim.scenario import load
from vehicle.applet import PREFIX, SCRIPT, TEXT_PREFIX

ROOT = Path(__file__).resolve().parents[1]


def script_params() -> dict[str, tuple[int, float]]:
    """name -> (index, default) of every parameter the script adds to its table."""
    found = re.findall(r'bind_add_param\("(\w+)", (\d+), ([\d.]+)\)', SCRIPT.read_text())
    return {PREFIX + name: (int(idx), float(default)) for name, idx, default in found}


def test_the_applet_flies_only_on_the_firmware_and_in_specs():
    assert flies(APPLET_POLICY, "ardurover") and not flies(APPLET_POLICY, "rover")
    assert not flies(APPLET_POLICY, "px4rover")
    assert plant_for("ardurover", APPLET_POLICY) is AppletPlant
    with pytest.raises(ValueError, match="Lua applet"):
        check_policy(APPLET_POLICY)
    spec = parse_spec('scenarios = ["tunnel"]\nvehicles = ["ardurover"]\nseeds = [1, 2]\n'
                      'policies = ["applet", "ardupilot-smartrtl"]\n', "s.toml")
    pairs = {(t.vehicle, t.policy) for t in spec.trials}
    assert pairs == {("ardurover", "applet"), ("ardurover", "ardupilot-smartrtl")}
    with pytest.raises(SpecError) as e:
        parse_spec('scenarios = ["tunnel"]\nvehicles = ["rover"]\npolicies = ["applet"]\n', "s.toml")
    assert e.value.field == "policies[0]" and "ardurover" in str(e.value)


def test_the_applet_spec_pairs_each_policy_with_its_vehicle():
    from sim.campaign.spec import load_spec

    spec = load_spec(ROOT / "sim" / "campaign" / "specs" / "applet.toml")
    pairs = {(t.vehicle, t.policy) for t in spec.trials}
    assert pairs == {("rover", "returnlink"), ("ardurover", "applet"), ("ardurover", "companion"),
                     ("ardurover", "ardupilot-smartrtl")}
    assert {t.scenario for t in spec.trials} == {"tunnel", "culvert", "building", "open"}
    assert len(spec.trials) == 4 * 20 * 4


def test_its_parameters_come_from_the_scenarios_own():
    p = applet_params(load("tunnel"))
    assert p["RLNK_TIMEOUT"] == 3.0 and p["RLNK_REGAIN_S"] == 1.0 and p["RLNK_SPACING"] == 0.5
    assert p["RLNK_MAX_DISP"] == 60.0  # the tunnel's plan: RETURN_TO_LINK with max_displacement 60
    assert set(p) <= set(MIRRORED) and set(p) <= set(script_params())


def test_the_parameter_table_is_documented_alike_in_the_script_and_the_docs():
    params = script_params()
    text = SCRIPT.read_text()
    assert len(params) == 14 and sorted(i for i, _ in params.values()) == list(range(1, 15))
    assert f'param:add_table(PARAM_TABLE_KEY, PARAM_PREFIX, {len(params)})' in text
    doc = (ROOT / "docs" / "applet.md").read_text()
    rows = dict(re.findall(r"^\| (RLNK_\w+) \|[^|]+\|[^|]*\| ([\d.]+) \|", doc, re.M))
    assert {k: float(v) for k, v in rows.items()} == {k: d for k, (_i, d) in params.items()}
    for name in params:
        assert f"// @Param: {name}" in text  # ArduPilot's own documentation block beside each
        assert re.search(rf"^    {name} +\S+ \S+ +\S+ +\S+", text, re.M), name  # the header's table


def test_every_text_fits_one_statustext():
    """ArduPilot splits a longer text in chunks of 50: the ground station (and our record) would see pieces."""
    text = SCRIPT.read_text()
    reasons = re.findall(r'start_braking\("([^"]+)"', text) + re.findall(r'return \w+, \w+, "([^"]+)"', text)
    longest = max(reasons, key=len)
    assert "link regained" in reasons and "max displacement" in reasons
    formats = re.findall(r'say\(\w+, (?:string\.format\()?"([^"]+)"', text)
    assert len(formats) >= 8
    for fmt in formats:  # at their widest: a distance of 9999.9 m, an hour, a mode number of three digits
        worst = fmt.replace("%.1f", "9999.9").replace("%.0f", "3600").replace("%d", "123").replace("%s", longest)
        assert len(TEXT_PREFIX + worst) <= 50, fmt


def fake_plant(modes, texts) -> AppletPlant:
    plant = AppletPlant.__new__(AppletPlant)
    plant.link = SimpleNamespace(tap=SimpleNamespace(modes=modes, texts=texts))
    return plant


def test_a_return_in_guided_reads_as_a_return_until_its_hold_shows():
    plant = fake_plant([(0.0, 0), (2.0, GUIDED), (60.6, HOLD), (62.0, GUIDED)],
                       [(49.2, "RLNK: return: silent 3.1 s, good 6.4 m back"), (60.5, "Throttle armed"),
                        (60.5, "RLNK: stopped: link regained, 11.3 s, 4.1 m")])
    assert plant.return_timeline == [(0.0, 0), (2.0, GUIDED), (49.2, RETURNING), (60.6, HOLD), (62.0, GUIDED)]


def test_a_return_the_pilot_ended_is_over_at_once():
    plant = fake_plant([(0.0, GUIDED)], [(10.0, "RLNK: return: silent 3.0 s, no good crumb"),
                                         (12.0, "RLNK: ended: pilot's target, 2.0 s")])
    assert plant.return_timeline == [(0.0, GUIDED), (10.0, RETURNING), (12.0, GUIDED)]


def heard(op: AppletOperator, t: float, mode: int, speed: float) -> None:
    op.mode, op.speed, op.last_position_t = mode, speed, t


def test_the_operator_keeps_its_hands_off_a_returning_rover_until_it_holds():
    op = AppletOperator([(40.0, 0.0, 1.2)], [(-5.0, 0.0, 1.5)], (-5.0, 0.0), applet_timeout=3.0)
    op.phase, op.armed, op.position = "driving", True, (30.0, 0.0)
    op.last_position_t = 10.0
    op._position_heard(14.0)  # 4 s without a position report: longer than the applet's timeout
    assert op.applet_busy
    heard(op, 14.0, GUIDED, 0.8)
    assert op.tick(14.0) == [] or op.sent_target is None  # a heartbeat at most, no target
    assert op.sent_target is None
    op._text_heard("RLNK: stopped: link regained, 11.3 s, 4.1 m", 15.0)
    heard(op, 15.2, HOLD, 0.0)
    op.tick(15.2)
    assert not op.applet_busy and op.phase == "resuming"  # took control back from HOLD, as after any failsafe


def test_the_operator_drives_again_if_nobody_returns_the_rover():
    op = AppletOperator([(40.0, 0.0, 1.2)], [(-5.0, 0.0, 1.5)], (-5.0, 0.0), applet_timeout=3.0)
    op.phase, op.armed, op.position = "driving", True, (30.0, 0.0)
    op._text_heard("RLNK: return: silent 3.1 s, good 6.4 m back", 10.0)
    for k in range(12):  # standing still in GUIDED for over REST_S: no applet at work
        heard(op, 10.0 + 0.2 * k, GUIDED, 0.0)
        op.tick(10.0 + 0.2 * k)
    # driving again: toward a waypoint of its own (the native steering: since issue 41 no position target)
    assert not op.applet_busy and op.heading_to is not None
