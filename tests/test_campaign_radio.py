"""The radio as a campaign axis: a spec's [radio] grid reaches the trial's scenario, errors are named by file,
line and field, and the summary keeps each radio strength on a line of its own with its link cycles."""

from __future__ import annotations

import pytest

from sim.campaign.spec import SpecError, parse_spec
from sim.campaign.store import summary
from sim.campaign.trial import scenario_of, simulate
from tests.campaign_helpers import quick_row

pytestmark = pytest.mark.slow


def test_a_radio_grid_multiplies_the_trials_and_reaches_their_scenario():
    spec = parse_spec('scenarios = ["tunnel"]\nseeds = [1]\n[radio]\npower_dbm = [-20, 20.0]\nexponent = [2.5]\n',
                      "s.toml")
    assert len(spec.trials) == 2 and len({t.id for t in spec.trials}) == 2
    weak = next(t for t in spec.trials if dict(t.params)["radio.power_dbm"] == -20.0)
    sc = scenario_of(weak)
    assert sc.station(sc.operator_station).power_dbm == -20.0 and sc.radio.exponent == 2.5
    assert "radio.power_dbm" not in sc.params  # a radio setting is not a vehicle parameter


def test_a_weaker_station_loses_the_link_sooner():
    spec = parse_spec('scenarios = ["tunnel"]\nseeds = [1]\n[radio]\npower_dbm = [-20, 20]\n', "s.toml")
    lost = {dict(t.params)["radio.power_dbm"]: simulate(t).metrics["link_lost_s"] for t in spec.trials}
    assert lost[-20.0] < lost[20.0]


@pytest.mark.parametrize("body, line, field, words", [
    ('scenarios = ["tunnel"]\n[radio]\nwatts = [1]\n', 3, "radio.watts", "unknown radio setting"),
    ('scenarios = ["tunnel"]\n[radio]\npower_dbm = [-20, 90]\n', 3, "radio.power_dbm", "within -40..40"),
    ('scenarios = ["tunnel"]\n[radio]\nexponent = []\n', 3, "radio.exponent", "at least one value"),
    ('scenarios = ["tunnel"]\nradio = 3\n', 2, "radio", "must be a table"),
])
def test_radio_grid_errors_name_file_line_and_field(body, line, field, words):
    with pytest.raises(SpecError) as e:
        parse_spec(body, "s.toml")
    assert (e.value.line, e.value.field) == (line, field) and words in str(e.value)


def test_the_summary_keeps_each_radio_strength_apart_with_its_link_cycles():
    spec = parse_spec('scenarios = ["tunnel"]\nseeds = [1, 2]\n[radio]\npower_dbm = [-20, 20]\n', "s.toml")
    rows = [quick_row(t, link_lost_s=10.0, link_regained_s=20.0,
                      link_cycles=3 if dict(t.params)["radio.power_dbm"] < 0 else t.seed - 1) for t in spec.trials]
    lines = {r["params"]: r for r in summary(rows)}
    assert len(lines) == 2
    weak = next(v for k, v in lines.items() if "-20" in k)
    strong = next(v for k, v in lines.items() if "-20" not in k)
    assert (weak["n"], weak["link_cycles_mean"], weak["link_cycles_max"]) == (2, 3.0, 3)
    assert (strong["link_cycles_mean"], strong["link_cycles_max"]) == (0.5, 1)
