"""The link map in whole simulated missions: what linkmap.csv says about the tunnel, and where returns end by it."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest

from link.linkmap_format import decode
from sim import outputs
from sim.campaign.spec import load_spec
from sim.runner import Run
from sim.scenario import load
from vehicle.linkmap import MapConfig

pytestmark = pytest.mark.slow


def test_tunnel_linkmap_csv_is_good_near_the_station_and_dead_deep_in_the_tunnel(tmp_path):
    run = Run(load("tunnel"), "rover", 1).run()
    run.metrics = outputs.compute(run)
    paths = outputs.write(run, tmp_path, plots=False)
    assert tmp_path / "linkmap.csv" in paths
    cells = decode((tmp_path / "linkmap.csv").read_bytes())
    loss_north = json.loads((tmp_path / "metrics.json").read_text())["loss_position"][0]
    threshold = MapConfig().threshold
    near = [c for c in cells if c.north < 20.0]  # the portal is at north 0, the station at -15
    deep = [c for c in cells if c.north > loss_north and c.observations >= 2]
    assert len(near) >= 8 and len(deep) >= 1
    assert all(c.delivery > 0.9 for c in near if c.observations >= 4)
    assert sum(c.lower > threshold for c in near) >= 8
    assert all(c.delivery < 0.1 for c in deep)
    assert any(c.rssi_dbm < -100 for c in deep)  # the vehicle's radio saw the signal die there


def test_a_return_to_the_maps_place_is_measured_against_that_place_not_the_crumb_target():
    # building, rover, seed 5: the last link-good crumb is deep in the far room, 4 m short of the doorway the map
    # vouches for; the return drives to the doorway, and the link comes back there (LINK_REGAINED over the regain
    # window, 12.1 s after the loss; before it came 13.5 s after, in the loiter that followed the block's arrival)
    run = Run(load("building"), "rover", 5).run()
    m = outputs.compute(run)
    first = run.blocks[0]
    assert first.command == "RETURN_TO_LINK" and first.reason == "LINK_REGAINED"
    assert m["regained_by"] == "return" and m["link_regained_s"] - m["link_lost_s"] < 15.0
    assert first.route_obj.by_map
    # the true place lies where the route's target is (the native estimator drifts well under a metre here)
    assert math.dist(first.target_true, first.target) < 1.0
    assert m["final_target_error_m"] < 1.5
    assert not m["failures"]


SPECS = Path(__file__).resolve().parents[1] / "sim" / "campaign" / "specs"


@pytest.mark.parametrize("spec", sorted(p.name for p in SPECS.glob("*.toml")))
def test_every_shipped_campaign_spec_and_its_worlds_load(spec):
    assert load_spec(SPECS / spec).trials


def test_where_the_stations_range_shrank_lnk_map_seek_looks_on_and_zero_stays():
    # the station's power falls 45 dB while the robot is in the adit: the place the map vouched for (recorded at
    # full power) no longer holds the link. At 0 the return stays there and the plan's 30 s loiter follows; at 40 m,
    # and by default, it carries on back along the trail, at RTL_APPROACH_SPD, to where the weaker station reaches.
    # (The world's own 40 dB drop no longer tells them apart: the map vouches only where a regain's 80 % came, deeper
    # toward the portal, and the weaker station still reaches there.)
    sc = load(str(SPECS / "worlds" / "shrink.toml"))
    sc = replace(sc, events=tuple(replace(e, value=-45.0) if e.action == "power" else e for e in sc.events))
    runs = {}
    for seek in (0.0, 40.0, None):
        params = {**sc.params, "LNK_MAP_SEEK": seek} if seek is not None else sc.params
        run = Run(replace(sc, params=params), "rover", 1).run()
        runs[seek] = (run, outputs.compute(run))
    (stay, m_stay), (seek, m_seek) = runs[0.0], runs[40.0]
    assert m_stay["loss_position"] == m_seek["loss_position"]  # the same drive out
    first = stay.blocks[0]
    assert first.route_obj.by_map and first.reason == "COMPLETED"
    assert stay.blocks[1].command == "LOITER"  # it waited where the map said the link was
    assert m_stay["link_regained_s"] - m_stay["link_lost_s"] > 45.0  # measured 49.5 s
    assert seek.blocks[0].reason == "LINK_REGAINED"  # in its first block, on past the place the map vouched for
    loss = m_seek["loss_position"]
    assert math.dist(seek.blocks[0].end, loss) > math.dist(first.end, loss) + 1.0
    assert m_seek["link_regained_s"] - m_seek["link_lost_s"] < 25.0  # measured 21.3 s
    assert m_seek["regained_by"] == "return" and m_seek["collisions"] == 0
    default = runs[None][1]
    assert default["link_regained_s"] == m_seek["link_regained_s"]  # seeking is the default


def test_a_seek_ends_where_another_station_is_heard():
    # handover, rover, seed 5: alpha (the owner) falls silent 58 m out, bravo is heard from 80 m. The return reaches
    # the place the map vouched for without alpha's link and would seek on back along the trail (by default): 44.6 m
    # back to alpha's dead station, away from bravo, had bravo's traffic not ended the seek (measured, the check
    # removed). It ends where it began, 12.8 m back, and bravo's takeover is granted after it
    run = Run(load("handover"), "rover", 5).run()
    m = outputs.compute(run)
    first = run.blocks[0]
    assert first.command == "RETURN_TO_LINK" and first.reason == "COMPLETED"
    assert first.distance < 20.0, f"sought on {first.distance:.1f} m with bravo heard"
    assert m["collisions"] == 0 and not m["failures"]
