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
