"""Scenario files: the built-ins load, and a broken file is reported by file, line and field."""

from __future__ import annotations

import pytest

from sim import scenario
from sim.scenario import ScenarioError

GOOD = """
name = "t"
duration = 10.0
[world]
bounds = [0, 0, 10, 10]
[[world.walls]]
points = [[1, 1], [2, 2]]
[[world.walls]]
points = [[1, 1], [2, 2]]
attenuation_db = "loud"
[[world.stations]]
name = "g"
position = [0, 0]
[start]
position = [1, 1]
[operator]
route = [[5, 5, 1.0]]
"""


@pytest.mark.parametrize("name", scenario.BUILTIN)
def test_builtin_scenarios_load(name):
    s = scenario.load(name)
    assert s.name == name and s.route and s.stations
    s.world()  # builds the pymunk space


def test_error_names_file_line_and_field():
    with pytest.raises(ScenarioError) as e:
        scenario.parse(GOOD, "bad.toml")
    assert e.value.field == "world.walls[1].attenuation_db"
    assert e.value.line == 10
    assert str(e.value).startswith("bad.toml:10: world.walls[1].attenuation_db: must be float")


@pytest.mark.parametrize("edit, field", [
    (("duration = 10.0", "duration = -3"), "duration"),
    (("[[5, 5, 1.0]]", "[[5, 5, 9.0]]"), "operator.route"),
    (('name = "g"', 'name = "g"\nsysid = 300'), "world.stations[0].sysid"),
    (("[operator]", "[operator]\nplan = [{command = \"FLY\"}]"), "operator.plan[0].command"),
    (("name = \"t\"", "name = \"t\"\nvehicle = \"boat\""), "vehicle"),
    (("name = \"t\"", "name = \"t\"\ncolour = 1"), "colour"),
])
def test_each_bad_field_is_named(edit, field):
    text = GOOD.replace('attenuation_db = "loud"', "attenuation_db = 3").replace(*edit)
    with pytest.raises(ScenarioError) as e:
        scenario.parse(text, "x.toml")
    assert e.value.field == field
    assert e.value.line is not None


def test_toml_syntax_error_has_a_line():
    with pytest.raises(ScenarioError) as e:
        scenario.parse("name = \n", "s.toml")
    assert e.value.line == 1


def test_missing_file():
    with pytest.raises(ScenarioError, match="no such scenario file"):
        scenario.load("/nonexistent/x.toml")


def test_scenario_plan_is_a_return_plan_mission():
    from vehicle.params import Params
    from vehicle.service import NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, NAV_RETURN_TO_LINK, blocks_from_items

    blocks = blocks_from_items(scenario.load("tunnel").plan, Params())
    assert [b.payload[0].command for b in blocks] == [NAV_RETURN_TO_LINK, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH]
    assert blocks[0].payload[0].param1 == 60.0 and blocks[1].payload[0].param1 == 30.0


FULL = GOOD.replace('attenuation_db = "loud"', "attenuation_db = 3").replace(
    "duration = 10.0", "duration = 10.0\nseed = 4").replace(
    "[operator]", "[operator]\nplan = [\n  { command = \"RETURN_TO_LINK\", max_displacement = 50 },\n"
                  "  { command = \"LOITER\", time = 5 },\n]\nparams = { LNK_TIMEOUT = 4 }")


@pytest.mark.parametrize("edit, field, needle", [
    # a misspelt key is an error naming it and the closest known key, at every level
    (("max_displacement = 50", "max_displacment = 50"), "operator.plan[0].max_displacment", "'max_displacement'"),
    (("time = 5", "tme = 5"), "operator.plan[1].tme", "did you mean 'time'"),
    (("[start]", "[start]\nyaw = 3"), "start.yaw", "did you mean 'yaw_deg'"),
    (("name = \"g\"", "name = \"g\"\npower = 3"), "world.stations[0].power", "'power_dbm'"),
    (("[world]", "[world]\nwals = []"), "world.wals", "did you mean 'walls'"),
    (("[operator]", "[operator]\nstaton = \"g\""), "operator.staton", "did you mean 'station'"),
    (("[operator]", "[criteria]\nlink_regaind = true\n[operator]"), "criteria.link_regaind", "'link_regained'"),
    (("[operator]", "[radio]\nexponnent = 2.0\n[operator]"), "radio.exponnent", "did you mean 'exponent'"),
    # NaN or infinity anywhere, even where it used to vanish (a wall point) or crash (the start)
    (("points = [[1, 1], [2, 2]]", "points = [[1, 1], [nan, 2]]"), "world.walls[0].points", "finite"),
    (("position = [1, 1]", "position = [nan, 1]"), "start.position", "finite"),
    (("[[5, 5, 1.0]]", "[[5, inf, 1.0]]"), "operator.route", "finite"),
    # seeds, parameters, walls, plan items checked as the vehicle would
    (("seed = 4", "seed = -5"), "seed", "0..4294967295"),
    (("LNK_TIMEOUT = 4", "NOPE = 3"), "operator.params.NOPE", "no vehicle parameter 'NOPE'"),
    (("LNK_TIMEOUT = 4", "LNK_TIMEOUT = 999"), "operator.params.LNK_TIMEOUT", "outside 0.5..120"),
    (("points = [[1, 1], [2, 2]]", "points = [[1, 1], [1, 1]]"), "world.walls[0].points", "zero length"),
    (("max_displacement = 50", "max_displacement = 50, target = 1.5"), "operator.plan[0].target", "whole number"),
    (("time = 5", "time = -1"), "operator.plan[1].time", "within"),
    (("[operator]", "[operator]\nattempts = 0"), "operator.attempts", "[1, 1000]"),
    (("[operator]", "[operator]\nattempts = 2.5"), "operator.attempts", "must be int"),
    (("[operator]", "[operator]\nrejoin = 1"), "operator.rejoin", "must be bool"),
    (("[operator]", "[[events]]\nt = 3\naction = \"param\"\nname = \"NOPE\"\n[operator]"), "events[0].name",
     "no vehicle parameter"),
    (("[operator]", "[criteria]\nchain_reasons = [\"DONE\"]\n[operator]"), "criteria.chain_reasons",
     "unknown reason"),
    (("[operator]", "[[events]]\nt = 3\naction = \"power\"\n[operator]"), "events[0].value", "needs the change"),
    (("[operator]", "[[events]]\nt = 3\naction = \"power\"\nvalue = -90\n[operator]"), "events[0].value",
     "within -70.0..70.0"),
])
def test_misspelt_nonfinite_and_out_of_range_fields_are_named(edit, field, needle):
    scenario.parse(FULL, "x.toml")  # the unedited text is fine
    assert edit[0] in FULL
    with pytest.raises(ScenarioError) as e:
        scenario.parse(FULL.replace(*edit, 1), "x.toml")
    assert e.value.field == field, str(e.value)
    assert needle in str(e.value)
    assert e.value.line is not None


def test_an_error_in_an_inline_plan_item_names_its_own_line():
    text = FULL.replace("time = 5", "tme = 5")
    with pytest.raises(ScenarioError) as e:
        scenario.parse(text, "x.toml")
    assert "tme = 5" in text.splitlines()[e.value.line - 1]
