"""One trajectory plot for every run (``sim.report.trajectory``): the paths it draws come from the lease trace where
returnlink flew, from an autopilot's own rows (with its modes) where one flew alone, from the served path in `sim
serve`; a return is marked by the return service's lease, or by the autopilot's return modes."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from sim.report import track, trajectory
from sim.scenario import load
from vehicle.lease import Holder

RTL, GUIDED = 11, 15
ROWS = [(0.02 * k, 1.0 * k, 2.0, 1.1 * k, 2.1, GUIDED if k < 3 else RTL) for k in range(1, 6)]


def _run(**what) -> SimpleNamespace:
    sc = load("open")
    plant = SimpleNamespace(rows=None, frame_offset=(0.0, 0.0), mode_names={RTL: "RTL", GUIDED: "GUIDED"},
                            return_modes=frozenset({RTL}))
    base = dict(scenario=sc, kind="ardurover", seed=1, policy="ardupilot-rtl", metrics=None, world=sc.world(),
                plant=plant, trace=None, vehicle=None, blocks=[], losses=[], link_backs=[], t=0.1, path=[])
    return SimpleNamespace(**{**base, **what})


def test_an_autopilot_alone_is_drawn_from_its_rows_by_mode():
    run = _run()
    run.plant.rows = ROWS
    tr = track(run)
    assert tr.true[:, 0].tolist() == [1.0, 2.0, 3.0, 4.0, 5.0] and tr.est[0].tolist() == [1.1, 2.1]
    assert tr.modes.tolist() == [GUIDED, GUIDED, RTL, RTL, RTL]
    assert tr.returning.tolist() == [False, False, True, True, True]


def test_returnlinks_leases_mark_the_return_where_they_flew():
    holder = [int(Holder.OPERATOR)] * 3 + [int(Holder.RETURN_SERVICE)] * 2
    trace = SimpleNamespace(rows=ROWS, true=[(r[1], r[2]) for r in ROWS], est=[(r[3], r[4]) for r in ROWS],
                            holder=holder)
    run = _run(trace=trace)
    run.plant.rows = [(*r[:5], GUIDED) for r in ROWS]  # a companion flies its return in GUIDED: the lease says it
    tr = track(run)
    assert tr.returning.tolist() == [False, False, False, True, True]


def test_a_served_run_is_drawn_from_its_path(tmp_path):
    run = _run(path=[(1.0, 2.0, 1.5, 2.5), (2.0, 2.0, 2.5, 2.5)])
    tr = track(run)
    assert tr.modes is None and tr.returning is None
    assert np.array_equal(tr.true, [[1.0, 2.0], [2.0, 2.0]]) and np.array_equal(tr.est, [[1.5, 2.5], [2.5, 2.5]])
    assert trajectory(run, tmp_path / "trajectory.png").stat().st_size > 10_000
