"""Generated worlds (docs/architecture.md §7.1): the same seed gives the same world, every world is valid, [generate]
files are range-checked by file, line and field, `sim world` writes a map and a scenario file that reads back as the
same world, and a campaign's generated trials hash the world they fly. Nothing here flies a run
(tests/test_worlds_runs.py does)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sim import scenario, worlds
from sim.campaign.spec import SpecError, parse_spec
from sim.campaign.trial import scenario_of
from sim.cli import main
from sim.scenario import ScenarioError
from sim.worlds import check, resolve
from sim.worlds.toml_out import to_toml

KINDS = tuple(worlds.FAMILIES)
SEEDS = range(31)


def same_but_file(a, b) -> bool:
    return dataclasses.replace(a, file="") == dataclasses.replace(b, file="")


def exits_2(args: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as e:
        raise SystemExit(main(args))
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


# ----- the generator --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
def test_the_same_seed_gives_the_same_world_and_another_seed_another(kind):
    a, redraws_a = worlds.generate(kind, 7)
    b, redraws_b = worlds.generate(kind, 7)
    assert a == b and redraws_a == redraws_b
    assert worlds.generate(kind, 8)[0].walls != a.walls
    assert a.seed == 7 and a.name == f"gen:{kind}"


@pytest.mark.parametrize("kind", KINDS)
def test_a_family_generate_is_pure_in_its_generator(kind):
    family = worlds.FAMILIES[kind]
    size = {name: lo for name, (lo, _hi) in family.SIZES.items()}
    assert family.generate(np.random.default_rng(3), **size) == family.generate(np.random.default_rng(3), **size)


@pytest.mark.parametrize("kind", KINDS)
def test_every_world_of_seeds_0_to_30_is_valid(kind):
    redraws = []
    for seed in SEEDS:
        sc, n = worlds.generate(kind, seed)
        redraws.append(n)
        v = check.check(sc)
        assert v.ok, (seed, v.problems)
        band = check.band_db(sc.radio)
        assert v.start_margin_db >= band  # alive at the start, shadowing's two spreads aside
        assert v.dead_at is not None and v.alive_at is not None  # dead on the route, after a place it was alive
        assert v.clearance_m >= check.CLEARANCE
        assert v.needed_displacement_m <= v.plan_displacement_m
        assert all(0 < p[2] <= 5 for p in sc.route + sc.resume_route)
        assert sc.criteria.return_started and sc.criteria.regained_by == "return"
    assert max(redraws) < worlds.REDRAWS


@pytest.mark.parametrize("kind", KINDS)
def test_the_ends_of_each_size_range_give_valid_worlds(kind):
    for name, (lo, hi) in worlds.sizes(kind).items():
        for value in (lo, hi):
            for seed in (1, 2):
                sc, _ = worlds.generate(kind, seed, {name: value})
                assert check.check(sc).ok
                assert f"{name} = {value}" in sc.description


def test_the_check_finds_an_undrivable_route_and_a_link_that_never_dies():
    sc, _ = worlds.generate("culvert", 1)
    assert check.check(sc).ok
    squeezed = dataclasses.replace(sc, walls=tuple(dataclasses.replace(w, thickness=w.thickness + 4.0)
                                                   for w in sc.walls))
    assert any("from a wall" in p for p in check.check(squeezed).problems)
    loud = dataclasses.replace(sc, walls=tuple(dataclasses.replace(w, attenuation_db=0.0) for w in sc.walls))
    assert any("never dies" in p for p in check.check(loud).problems)


def test_the_steered_path_cuts_a_corner_as_the_operator_does():
    path = check.steered_path((0.0, 0.0), ((10.0, 0.0, 1.0), (10.0, 10.0, 1.0)))
    assert path[1] == pytest.approx((8.5, 0.0))  # turns for the next waypoint WAYPOINT_RADIUS before this one
    assert math.dist(path[-1], (10.0, 10.0)) == pytest.approx(1.5)


def test_no_valid_draw_within_the_budget_is_a_clear_error(monkeypatch):
    never = check.Verdict(("nothing works",), 0.0, 0.0, None, None, None, None)
    monkeypatch.setattr(worlds.office, "check_world", lambda sc: never)
    with pytest.raises(worlds.WorldError, match=r"no valid office world from seed 4 in 50 draws.*nothing works"):
        worlds.generate("office", 4)


def test_unknown_family_and_bad_sizes_are_refused():
    with pytest.raises(worlds.WorldError, match="unknown world family 'castle'"):
        worlds.generate("castle", 1)
    with pytest.raises(worlds.WorldError, match=r"rooms must be within 2..20, got 21"):
        worlds.generate("office", 1, {"rooms": 21})
    with pytest.raises(worlds.WorldError, match="no size 'floors'"):
        worlds.generate("office", 1, {"floors": 2})


# ----- names and [generate] files ---------------------------------------------------------------------------
def load(name: str, seed: int | None = None):
    return resolve.load(name, seed)[0]


def test_gen_names_load_the_world_of_the_seed():
    assert same_but_file(load("gen:mine", 5), worlds.generate("mine", 5)[0])
    assert load("gen:mine").seed == 1  # no seed: the scenario files' default
    assert resolve.load("tunnel") == (scenario.load("tunnel"), None)  # not generated
    with pytest.raises(ScenarioError, match="unknown world family 'castle'"):
        load("gen:castle")


def test_sim_scenario_alone_refuses_a_generate_file_by_its_line():
    with pytest.raises(ScenarioError) as e:
        scenario.parse(GENERATE, "g.toml")
    assert (e.value.field, e.value.line) == ("generate", 5)


GENERATE = """name = "my office"
seed = 4
duration = 150.0

[generate]
kind = "office"
rooms = 6
"""


def test_a_generate_file_is_a_world_of_its_family_with_its_own_name_seed_and_duration(tmp_path):
    path = tmp_path / "office.toml"
    path.write_text(GENERATE)
    sc = load(str(path))
    assert sc.name == "my office" and sc.seed == 4 and sc.duration == 150.0 and sc.file == str(path)
    assert "rooms = 6" in sc.description
    assert sc.walls == worlds.generate("office", 4, {"rooms": 6})[0].walls
    assert load(str(path), 9).walls == worlds.generate("office", 9, {"rooms": 6})[0].walls


@pytest.mark.parametrize("edit, fld, line", [
    (("rooms = 6", "rooms = 21"), "generate.rooms", 7),
    (("rooms = 6", "rooms = 1"), "generate.rooms", 7),
    (("rooms = 6", 'rooms = "six"'), "generate.rooms", 7),
    (('kind = "office"', 'kind = "castle"'), "generate.kind", 6),
    (("rooms = 6", "floors = 2"), "generate.floors", 7),
    (("rooms = 6", "rooms = 6\nbends = 2"), "generate.bends", 8),
    (("duration = 150.0", "duration = 150.0\n[world]\nbounds = [0, 0, 1, 1]"), "world", 4),
    (("seed = 4", "seed = 4\ncolour = 1"), "colour", 3),
])
def test_a_bad_generate_field_is_named_by_file_line_and_field(tmp_path, capsys, edit, fld, line):
    path = tmp_path / "bad.toml"
    path.write_text(GENERATE.replace(*edit))
    with pytest.raises(ScenarioError) as e:
        load(str(path))
    assert (e.value.field, e.value.line) == (fld, line)
    err = exits_2(["sim", "run", str(path), "--quiet"], capsys)
    assert f"{path}:{line}: {fld}:" in err


def test_an_unknown_family_exits_2_naming_it(capsys):
    assert "unknown world family 'castle'" in exits_2(["sim", "run", "gen:castle", "--quiet"], capsys)
    assert "unknown world family 'castle'" in exits_2(["sim", "world", "gen:castle", "--out", "/tmp/x"], capsys)


def test_an_exhausted_redraw_budget_exits_2_naming_the_family_and_seed(monkeypatch, capsys, tmp_path):
    never = check.Verdict(("nothing works",), 0.0, 0.0, None, None, None, None)
    monkeypatch.setattr(worlds.mine, "check_world", lambda sc: never)
    err = exits_2(["sim", "world", "gen:mine", "--seed", "12", "--out", str(tmp_path)], capsys)
    assert "no valid mine world from seed 12" in err


# ----- world.toml and world.png -----------------------------------------------------------------------------
@pytest.mark.parametrize("name", scenario.BUILTIN)
def test_every_builtin_scenario_reads_back_from_its_written_file(name):
    sc = scenario.load(name)
    assert same_but_file(scenario.parse(to_toml(sc), "w.toml"), sc)


@pytest.mark.parametrize("kind", KINDS)
def test_a_generated_world_reads_back_from_its_written_file(kind):
    for seed in (0, 3, 11):
        sc = load(f"gen:{kind}", seed)
        text = to_toml(sc)
        assert "[generate]" not in text
        assert same_but_file(scenario.parse(text, "world.toml"), sc)


def test_sim_world_writes_the_map_and_a_scenario_file_of_the_same_world(tmp_path, capsys):
    out = tmp_path / "w"
    assert main(["sim", "world", "gen:office", "--seed", "3", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "redrawn" in printed and "seed 3" in printed
    assert (out / "world.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert same_but_file(scenario.load(str(out / "world.toml")), load("gen:office", 3))
    assert main(["sim", "world", "tunnel", "--out", str(tmp_path / "t")]) == 0  # a built-in one renders too
    assert "not generated" in capsys.readouterr().out
    assert (tmp_path / "t" / "world.png").is_file()


# ----- campaigns ------------------------------------------------------------------------------------------------
def test_a_sweep_of_a_family_flies_one_world_per_seed_and_hashes_it(tmp_path):
    spec_text = 'scenarios = ["gen:culvert"]\nseeds = [1, 2]\n'
    spec = parse_spec(spec_text, str(tmp_path / "s.toml"), tmp_path)
    assert [t.seed for t in spec.trials] == [1, 2]
    assert spec.trials[0].scenario_text != spec.trials[1].scenario_text
    for t in spec.trials:
        assert t.scenario == "gen:culvert" and t.source == "gen:culvert"
        assert same_but_file(scenario_of(t), load("gen:culvert", t.seed))
    again = parse_spec(spec_text, str(tmp_path / "s.toml"), tmp_path)
    assert [t.id for t in again.trials] == [t.id for t in spec.trials]  # a resumed campaign finds its trials


def test_a_sweep_of_a_generate_file_and_a_bad_family(tmp_path):
    (tmp_path / "o.toml").write_text(GENERATE)
    spec = parse_spec('scenarios = ["o.toml"]\nseeds = [5]\n', str(tmp_path / "s.toml"), tmp_path)
    assert same_but_file(scenario_of(spec.trials[0]), load(str(tmp_path / "o.toml"), 5))
    with pytest.raises(SpecError) as e:
        parse_spec('scenarios = ["gen:castle"]\nseeds = [1]\n', str(tmp_path / "s.toml"), tmp_path)
    assert e.value.field == "scenarios[0]" and "unknown world family" in str(e.value)
