"""The link map in whole simulated missions: what linkmap.csv says about the tunnel, and where returns end by it."""

from __future__ import annotations

import json
import math

from link.linkmap_format import decode
from sim import outputs
from sim.runner import Run
from sim.scenario import load
from vehicle.linkmap import MapConfig


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
    # vouches for; the return drives to the doorway, so that is where its final target error is measured from
    run = Run(load("building"), "rover", 5).run()
    m = outputs.compute(run)
    first = run.blocks[0]
    assert first.command == "RETURN_TO_LINK" and first.reason == "COMPLETED"
    assert first.route_obj.by_map
    # the true place lies where the route's target is (the native estimator drifts well under a metre here)
    assert math.dist(first.target_true, first.target) < 1.0
    assert m["final_target_error_m"] < 1.5
    assert not m["failures"]
