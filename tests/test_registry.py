"""The one registry of plants (docs/architecture.md §2, issue 39 item 2): every plant class says what the registry
says it flies, the registry answers for every pair, and no module outside it branches on a vehicle or policy name
or loads a module from a string."""

from __future__ import annotations

import ast
import itertools
import re
from pathlib import Path

import pytest

from sim import registry
from sim.plants import registry as plants
from sim.robots import ROBOTS

ROOT = Path(__file__).resolve().parent.parent
NAMES = frozenset(registry.VEHICLES) | frozenset(registry.POLICY_NAMES)
HOME = ROOT / "sim" / "registry.py"


@pytest.mark.parametrize("entry", registry.PLANTS, ids=lambda e: e.name)
def test_each_plant_class_declares_what_its_entry_flies(entry):
    cls = plants.plant_class(entry)
    assert tuple(cls.policies) == entry.policies
    if entry is not registry.NATIVE_PLANT:  # the native plant takes its robot's kind when made
        assert cls.kind in entry.vehicles


def test_every_pair_a_plant_flies_finds_that_plant_and_no_other_pair_flies():
    for vehicle, policy in itertools.product(registry.VEHICLES, registry.POLICY_NAMES):
        entry = registry.plant_entry(vehicle, policy)
        assert registry.flies(policy, vehicle) == (vehicle in entry.vehicles and policy in entry.policies)
        assert vehicle in entry.vehicles  # a pair no plant flies goes to the vehicle's own plant, which refuses it
    assert {e for e, _ in plants.CLASSES} == set(registry.PLANTS)


def test_every_vehicle_flies_its_default_and_every_policy_has_a_vehicle():
    for v in registry.VEHICLES_TABLE:
        assert registry.flies(v.default_policy, v.name)
    assert all(registry.vehicles_for(p) for p in registry.POLICY_NAMES)
    assert tuple(ROBOTS) == registry.NATIVE_VEHICLES  # a native vehicle is a robot body the scenario names


def test_refusals_name_the_vehicle_that_flies_the_policy():
    assert registry.why_not("companion", "rover") == ("policy companion runs beside a real autopilot: use --vehicle "
                                                      "ardurover or px4rover")
    assert registry.why_not("px4-hold", "legged") == "policy px4-hold needs PX4: use --vehicle px4rover"
    assert registry.why_not("hold", "px4rover").startswith("vehicle px4rover flies PX4's own data-link failsafe")
    assert registry.spec_need("hold") == "a native vehicle (rover, legged)"
    assert registry.spec_need("companion") == "vehicle 'ardurover' or 'px4rover'"
    with pytest.raises(ValueError, match="fly it with vehicle 'ardurover'$"):
        registry.check_native_policy("ardupilot-rtl")


def test_the_command_line_offers_the_registry_s_choices():
    import argparse

    from sim.cli import run, serve

    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    run.add_parser(sub)
    serve.add_parser(sub)
    for name in ("run", "serve"):
        actions = {a.dest: a for a in sub.choices[name]._actions}
        assert tuple(actions["vehicle"].choices) == registry.VEHICLES
    assert tuple(sub.choices["run"]._option_string_actions["--policy"].choices) == registry.POLICY_NAMES
    assert tuple(sub.choices["serve"]._option_string_actions["--policy"].choices) == registry.autopilot_policies()


def _branches_on_names(tree: ast.AST) -> list[int]:
    """Lines comparing a vehicle, kind or policy with one of their names written out (==, !=, in, not in, is).
    "rtl" or "hold" compared with a scenario event's action or an operator's phase is no such branch: the other
    side must be named after a vehicle, a kind or a policy."""
    def literals(node: ast.AST) -> set[str]:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return {node.value}
        if isinstance(node, ast.Tuple | ast.List | ast.Set):
            return set().union(*(literals(e) for e in node.elts)) if node.elts else set()
        return set()

    def about_names(node: ast.AST) -> bool:
        return bool(re.search(r"vehicle|kind|polic|\bpol\b|\bveh\b", ast.unparse(node)))

    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            sides = (node.left, *node.comparators)
            if any(literals(s) & NAMES for s in sides) and any(about_names(s) for s in sides if not literals(s)):
                lines.append(node.lineno)
    return lines


def _loads_from_a_string(tree: ast.AST) -> list[int]:
    """Lines that import a module by a name in a string (importlib.import_module, __import__)."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if name in ("import_module", "__import__"):
                out.append(node.lineno)
    return out


def _sources() -> list[Path]:
    return sorted(p for room in ("sim", "gcs", "benchmarks") for p in (ROOT / room).rglob("*.py") if p != HOME)


def test_nothing_outside_the_registry_branches_on_a_vehicle_or_policy_name():
    found = [f"{p.relative_to(ROOT)}:{line}" for p in _sources()
             for line in _branches_on_names(ast.parse(p.read_text(encoding="utf-8")))]
    assert found == []


def test_no_plant_or_module_is_loaded_from_a_string():
    found = [f"{p.relative_to(ROOT)}:{line}" for p in _sources()
             for line in _loads_from_a_string(ast.parse(p.read_text(encoding="utf-8")))]
    assert found == []


def test_the_checks_see_a_branch_and_a_string_import():
    assert _branches_on_names(ast.parse('if kind == "rover":\n    pass\n')) == [1]
    assert _branches_on_names(ast.parse('ok = policy not in ("hold", "x")\n')) == [1]
    assert _branches_on_names(ast.parse('ok = mode == "HOLD"\n')) == []
    assert _branches_on_names(ast.parse('ok = ev.action == "rtl"\n')) == []  # a scenario event, not a policy
    assert _loads_from_a_string(ast.parse('m = importlib.import_module("sim.plants.px4")\n')) == [1]
