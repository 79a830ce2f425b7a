"""reaction_latency_s is measured from the moment the trigger's condition became true (docs/architecture.md §6):
LNK_TIMEOUT after the owner was last heard, or the owner's delivery falling below LNK_MIN_Q, whichever came
first, so it is never negative. Culvert seed 3 loses its link by the quality trigger while packets still arrive."""

from __future__ import annotations

import pytest

from sim import metrics
from sim.runner import Run
from sim.scenario import load

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def culvert():
    return {p: Run(load("culvert"), "rover", 3, policy=p).run() for p in ("returnlink", "smartrtl")}


def test_a_quality_loss_is_reacted_to_in_its_tick_not_3_s_early(culvert):
    run = culvert["returnlink"]
    m = metrics.compute(run)
    t_loss, heard = run.losses[0]
    timeout = run.vehicle.params["LNK_TIMEOUT"]
    assert t_loss < heard + timeout  # the quality trigger fired before any silence timed out
    assert run.loss_conditions[0] == pytest.approx(t_loss)
    assert m["reaction_latency_s"] == 0.0


def test_a_baseline_that_waits_fs_timeout_shows_it(culvert):
    m = metrics.compute(culvert["smartrtl"])
    assert m["reaction_latency_s"] == pytest.approx(1.5, abs=0.021)  # ArduPilot's FS_TIMEOUT, within a tick
