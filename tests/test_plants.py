"""One simulator loop, many plants (sim/plants): every plant answers the whole ``Plant`` port, the loop picks the
plant from the vehicle and the policy, and the one metrics pipeline and verdict treat every plant alike: the
contract's keys in order, the plant's own keys after them, and the lease criteria judged only where leases fly.
No firmware is started here: the firmware's plants are checked as classes, the pipeline on a native run."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import pytest

from sim import metrics
from sim.plants import Plant
from sim.plants.companion import CompanionPlant
from sim.plants.firmware import FirmwarePlant
from sim.plants.native import NativePlant
from sim.runner import Run, plant_for
from sim.scenario import Criteria, load

PLANTS = (NativePlant, FirmwarePlant, CompanionPlant)
# what the port declares: annotated attributes and methods (the docstring-only bodies of the protocol)
PORT = set(Plant.__annotations__) | {n for n, v in vars(Plant).items() if callable(v) or isinstance(v, property)
                                     if not n.startswith("_")}


@pytest.mark.parametrize("plant", PLANTS, ids=lambda p: p.__name__)
def test_every_plant_answers_the_whole_port(plant):
    # made, never started: the firmware's process starts only in ``start``, so no binary is needed here
    made = plant(load("tunnel"), "rover" if plant is NativePlant else "ardurover", 1,
                 {NativePlant: "returnlink", FirmwarePlant: "ardupilot-hold", CompanionPlant: "companion"}[plant],
                 **({} if plant is NativePlant else {"firmware": Path("/nowhere/ardurover")}))
    assert {n for n in PORT if not hasattr(made, n)} == set()
    assert (made.rows is None) == (plant is NativePlant) and made.leases == (plant is not FirmwarePlant)


def test_the_loop_picks_the_plant_by_vehicle_and_policy():
    assert plant_for("rover", "returnlink") is NativePlant and plant_for("legged", "smartrtl") is NativePlant
    assert plant_for("ardurover", "ardupilot-hold") is FirmwarePlant
    assert plant_for("ardurover", "companion") is CompanionPlant
    with pytest.raises(ValueError, match="ardurover"):
        Run(load("open"), "rover", policy="companion")  # the native vehicle cannot fly the companion
    with pytest.raises(ValueError, match="not one of"):
        FirmwarePlant(load("open"), "ardurover", 1, "returnlink", firmware=None)


def test_the_pipeline_keeps_the_contract_order_and_adds_the_plants_keys_after_it():
    run = Run(load("open"), "rover", 1, duration=2.0).run()
    m = metrics.compute(run)
    assert tuple(m) == metrics.KEYS
    figures = run.plant.figures
    run.plant.figures = lambda r: {**figures(r), "firmware": "X", "firmware_modes": []}
    assert tuple(metrics.compute(run)) == (*metrics.KEYS, "firmware", "firmware_modes")
    run.plant.figures = lambda r: {k: v for k, v in figures(r).items() if k != "blocks"}
    with pytest.raises(KeyError, match="blocks"):  # a figure the plant does not give is an error, not a gap
        metrics.compute(run)


def test_the_one_verdict_judges_the_lease_criteria_only_where_leases_fly():
    criteria = Criteria(return_started=True, max_final_target_error_m=2.0, min_commands_rejected=1,
                        chain_reasons=("LINK_REGAINED",))
    run = SimpleNamespace(scenario=SimpleNamespace(criteria=criteria), blocks=[])
    m = {"stale_commands_executed": None, "return_started_s": 40.0, "link_regained_s": None,
         "final_target_error_m": None, "collisions": 0, "distance_back_m": 3.0, "commands_rejected": 0,
         "regained_by": None}
    leased = metrics.verdict(run, m)
    assert leased == ["no return target to measure against", "0 commands rejected < 1",
                      "return blocks ended [], expected ['LINK_REGAINED']"]
    assert metrics.verdict(run, m, leases=False) == []  # the firmware alone: none of those applies
    run.scenario.criteria = dataclasses.replace(criteria, max_collisions=0)
    assert metrics.verdict(run, {**m, "collisions": 2}, leases=False) == ["2 collisions > 0"]
