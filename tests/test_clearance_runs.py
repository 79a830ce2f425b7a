"""Corners cut through seen free space in a whole run (vehicle/clearance.py, docs/architecture.md §6 "Route"): in
the building, the rover's return crosses the far room to the doorway instead of retracing the operator's L along
its walls, gets the link back sooner and touches nothing; at RTL_CUT_CLR 0 it retraces the crumbs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sim import outputs
from sim.runner import Run
from sim.scenario import load

pytestmark = pytest.mark.slow


def _run(clearance: float):
    sc = load("building")
    run = Run(replace(sc, params={**sc.params, "RTL_CUT_CLR": clearance}), "rover", 5).run()
    return run, outputs.compute(run)


def _length(points: np.ndarray) -> float:
    return float(np.hypot(*np.diff(points, axis=0).T).sum())


def test_the_building_return_cuts_across_the_room_it_saw_and_touches_nothing():
    (cut, m_cut), (crumbs, m_crumbs) = _run(0.9), _run(0.0)
    assert m_cut["loss_position"] == m_crumbs["loss_position"]  # the same drive out
    route_cut, route_crumbs = cut.blocks[0].route_obj, crumbs.blocks[0].route_obj
    # the same way back, fewer corners: a metre less path to the doorway the map vouches for
    assert route_cut.by_map and route_crumbs.by_map
    assert np.allclose(route_cut.points[-1], route_crumbs.points[-1], atol=0.3)
    assert _length(route_cut.points) < _length(route_crumbs.points) - 0.5
    assert len(route_cut.points) < len(route_crumbs.points)
    # sooner back in touch, and no wall touched by either return
    assert m_cut["link_regained_s"] < m_crumbs["link_regained_s"] - 0.5
    assert m_cut["collisions"] == 0 and m_crumbs["collisions"] == 0
    assert m_cut["regained_by"] == "return" and not m_cut["failures"]
