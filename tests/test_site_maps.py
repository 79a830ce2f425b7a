"""Your own site (docs/architecture.md §7.2), without flying: a map_server map read as ROS reads it, its errors by
file, line and field, the grid's walls, radio loss and range beams, the station's checks, routes drawn to where the
link dies, [map] scenario files and `map:` names, and the predicted coverage. Runs are in tests/test_site_runs.py."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from PIL import Image

from link.radio import RadioParams
from sim import scenario
from sim.maps import coverage, mapfile
from sim.maps.grid import Grid, Site
from sim.scenario import ScenarioError
from sim.worlds import check, resolve
from sim.worlds import map_routes as routes
from sim.worlds.toml_out import to_toml
from tests import site_maps


@pytest.fixture(scope="module")
def building(tmp_path_factory):
    return site_maps.building(tmp_path_factory.mktemp("building"))


def write_map(tmp_path, cells, extra: str = "", name: str = "m.pgm", **kw):
    site_maps.write_pgm(tmp_path / name, cells, **kw) if name.endswith(".pgm") else \
        Image.fromarray(cells).save(tmp_path / name)
    return site_maps.write_yaml(tmp_path / "m.yaml", name, 0.5, extra=extra)


# ----- reading the map ------------------------------------------------------------------------------------------
def test_trinary_cells_follow_map_servers_thresholds_and_the_bottom_row_is_row_zero(tmp_path):
    cells = np.array([[0, 100, 254], [205, 90, 80]], dtype=np.uint8)  # top row first, as in the image
    m = mapfile.read(write_map(tmp_path, cells))
    # p = (255 - v) / 255: 0 -> 1.0 occupied, 100 -> 0.61 unknown, 254 -> 0.004 free, 205 -> 0.196 unknown
    # (not < free_thresh 0.196), 90 -> 0.647 unknown (not > 0.65), 80 -> 0.686 occupied
    assert m.occupied.tolist() == [[False, False, True], [True, False, False]]
    assert m.free.tolist() == [[False, False, False], [False, False, True]]
    assert m.unknown.tolist() == [[True, True, False], [False, True, False]]


def test_negate_flips_the_shade_and_16_bit_and_png_read_the_same(tmp_path):
    cells = np.array([[0, 254, 205]], dtype=np.uint8)
    plain = mapfile.read(write_map(tmp_path, cells))
    (tmp_path / "n").mkdir()
    neg = mapfile.read(write_map(tmp_path / "n", 255 - cells, extra="", name="m.pgm"))
    assert neg.occupied.tolist() == [[False, True, True]] != plain.occupied.tolist()  # 50: p 0.8
    path = site_maps.write_yaml(tmp_path / "n" / "m.yaml", "m.pgm", 0.5)
    path.write_text(path.read_text().replace("negate: 0", "negate: 1"))
    assert mapfile.read(path).occupied.tolist() == plain.occupied.tolist()
    (tmp_path / "w").mkdir()
    wide = mapfile.read(write_map(tmp_path / "w", cells.astype(np.uint16) * 257))
    assert wide.occupied.tolist() == plain.occupied.tolist() and wide.free.tolist() == plain.free.tolist()
    (tmp_path / "p").mkdir()
    png = mapfile.read(write_map(tmp_path / "p", cells, name="m.png"))
    assert png.occupied.tolist() == plain.occupied.tolist() and png.free.tolist() == plain.free.tolist()
    (tmp_path / "a").mkdir()
    ascii_ = mapfile.read(write_map(tmp_path / "a", cells, binary=False))
    assert ascii_.free.tolist() == plain.free.tolist()


def test_raw_and_scale_modes():
    gray = np.array([[0.0, 100.0, 50.0, 255.0]])
    occ, free = mapfile.classify(gray, None, False, 0.65, 0.196, "raw")  # the value is the percentage itself
    assert occ.tolist() == [[False, True, False, False]] and free.tolist() == [[True, False, False, False]]
    alpha = np.array([[1.0, 0.5, 1.0, 1.0]])
    occ, free = mapfile.classify(np.array([[0.0, 0.0, 254.0, 254.0]]), alpha, False, 0.65, 0.196, "scale")
    assert occ.tolist() == [[True, False, False, False]]  # not opaque: unknown
    assert free.tolist() == [[False, False, True, True]]


@pytest.mark.parametrize(("yaml", "field"), [
    ("resolution: 0.1\n", "image"),
    ("image: m.pgm\n", "resolution"),
    ("image: m.pgm\nresolution: -1\n", "resolution"),
    ("image: m.pgm\nresolution: 0.1\noccupied_thresh: 1.5\n", "occupied_thresh"),
    ("image: m.pgm\nresolution: 0.1\nfree_thresh: 0.7\n", "free_thresh"),
    ("image: m.pgm\nresolution: 0.1\nmode: fancy\n", "mode"),
    ("image: m.pgm\nresolution: 0.1\norigin: [1, 2]\n", "origin"),
    ("image: nothere.pgm\nresolution: 0.1\n", "image"),
    ("image: m.pgm\nresolution: [0.1\n", ""),
])
def test_a_bad_map_names_its_file_and_field(tmp_path, yaml, field):
    site_maps.write_pgm(tmp_path / "m.pgm", np.full((3, 3), 254, dtype=np.uint8))
    (tmp_path / "m.yaml").write_text(yaml)
    with pytest.raises(mapfile.MapError) as e:
        mapfile.read(tmp_path / "m.yaml")
    assert e.value.field == field and "m.yaml" in str(e.value)
    if field in ("resolution", "occupied_thresh", "free_thresh", "mode", "origin") and "\n" in yaml[:-1]:
        assert e.value.line == yaml.count("\n", 0, yaml.index(field)) + 1


def test_an_image_that_cannot_be_read_is_an_error_naming_the_image(tmp_path):
    (tmp_path / "m.pgm").write_bytes(b"P5\n3 3\n255\n\x00")  # cut short
    site_maps.write_yaml(tmp_path / "m.yaml", "m.pgm", 0.1)
    with pytest.raises(mapfile.MapError) as e:
        mapfile.read(tmp_path / "m.yaml")
    assert e.value.field == "image"


# ----- the grid -------------------------------------------------------------------------------------------------
def small_grid(yaw: float = 0.0) -> Grid:
    solid = np.zeros((10, 20), dtype=bool)
    solid[4:6, 5:15] = True  # a wall 1 m thick (v 2..3 m), 5 m long (u 2.5..7.5 m)
    return Grid(solid, 0.5, (0.0, 0.0, yaw), outside_solid=True)


def test_walls_are_merged_runs_of_cell_edges_with_the_map_border():
    e = small_grid().edges()
    assert len(e) == 8  # the wall's four sides and the map's four borders, each one straight run
    assert [2.5, 2.0, 7.5, 2.0] in e.tolist() and [0.0, 0.0, 10.0, 0.0] in e.tolist()


def test_the_line_of_sight_counts_runs_and_metres_of_solid_cells():
    g = small_grid()
    assert g.crossed((1.0, 1.0), (4.5, 1.0)) == (0, 0.0)  # beside the wall
    runs, metres = g.crossed((1.0, 4.0), (4.5, 4.0))  # north through it at u = 4 (world: north, east)
    assert runs == 1 and metres == pytest.approx(1.0, abs=0.3)


def test_range_beams_stop_at_solid_cells():
    g = small_grid()
    r = g.ranges(1.0, 4.0, np.array([0.0, math.pi / 2]), 20.0)  # north to the wall, east to the map's edge
    assert r[0] == pytest.approx(1.0, abs=0.25) and r[1] == pytest.approx(6.0, abs=0.25)
    assert np.isinf(g.ranges(1.0, 4.0, np.array([0.0]), 0.5))[0]


def test_a_turned_map_puts_its_cells_where_its_origin_yaw_says():
    g = small_grid(yaw=math.pi / 2)  # u now points north, v west
    n, e = g.cell_centre(np.array([0]), np.array([0]))
    assert (float(n[0]), float(e[0])) == pytest.approx((0.25, -0.25))
    assert g.is_solid(5.0, -2.5) and not g.is_solid(5.0, -1.0)


def test_the_station_must_stand_on_an_open_cell_of_the_map():
    g = small_grid()
    assert g.station_problem(1.0, 1.0) is None
    assert "off the map" in g.station_problem(-1.0, 1.0)
    assert "occupied" in g.station_problem(2.5, 4.0)


# ----- routes ----------------------------------------------------------------------------------------------------
def test_a_route_goes_from_the_station_to_where_the_mean_link_is_dead_with_room_to_drive(building):
    site = Site(str(building.resolve()))
    station = scenario.Station("gcs", site_maps.STATION[1], site_maps.STATION[0])
    for seed in (1, 2, 3):
        sc, redraws = routes.draw(site, station, RadioParams(), seed, "map:building")
        verdict = check.check(sc)
        assert verdict.ok, verdict.problems
        assert routes.route_clearance(sc) >= check.CLEARANCE - 0.05
        assert math.dist(sc.start[:2], (station.x, station.y)) < routes.START_REACH
        again, _ = routes.draw(site, station, RadioParams(), seed, "map:building")
        assert again == sc  # the same seed, the same route


def test_no_place_where_the_link_dies_is_an_error(building):
    site = Site(str(building.resolve()))
    strong = RadioParams(exponent=1.5)
    with pytest.raises(routes.RouteError, match="no reachable place where the link dies"):
        routes.draw(site, scenario.Station("gcs", 12.0, 1.5, 255, 40.0), strong, 1, "x")


def test_map_names_and_map_tables_with_their_errors(building, tmp_path):
    sc, redraws = resolve.load(f"map:{building}", 2, station=site_maps.STATION)
    assert sc.site is not None and redraws is not None and sc.walls == ()
    assert sc.stations[0].x == site_maps.STATION[1] and sc.stations[0].y == site_maps.STATION[0]  # north, east
    with pytest.raises(ScenarioError) as e:
        resolve.load(f"map:{building}", 2)
    assert e.value.field == "station"
    for bad, why in (((100.0, 12.0), "off the map"), ((0.05, 2.1), "occupied")):
        with pytest.raises(ScenarioError) as e:
            resolve.load(f"map:{building}", 2, station=bad)
        assert e.value.field == "map.station" and why in str(e.value)
    # a scenario file with [map]: the file relative to it, an unknown key named, the map's written form
    (tmp_path / "s.toml").write_text(f'name = "s"\n[map]\nfile = "{building}"\nstation = [1.5, 12.0]\nwal_db = 3\n')
    with pytest.raises(ScenarioError) as e:
        resolve.load(str(tmp_path / "s.toml"), 1)
    assert e.value.field == "map.wal_db" and e.value.line == 5
    text = to_toml(sc)
    assert "[map]" in text and "walls" not in text
    back = scenario.parse(text, "world.toml")
    assert dataclasses.replace(back, file="") == dataclasses.replace(sc, file="")
    changed = text.replace(sc.site.digest, "0" * 16)
    with pytest.raises(ScenarioError) as e:
        scenario.parse(changed, "world.toml")
    assert e.value.field == "map.digest"


def test_a_radio_file_changes_the_world_it_is_given_to(building, tmp_path):
    (tmp_path / "r.toml").write_text("[radio]\nexponent = 2.6\nwall_db = 12.5\n")
    sc, _ = resolve.load(f"map:{building}", 2, station=site_maps.STATION,
                         radio=scenario.read_radio_file(str(tmp_path / "r.toml")))
    assert sc.radio.exponent == 2.6 and sc.site.wall_db == 12.5
    (tmp_path / "bad.toml").write_text("[radio]\nexponent = 2.6\nwall_dB = 1\n")
    with pytest.raises(ScenarioError) as e:
        scenario.read_radio_file(str(tmp_path / "bad.toml"))
    assert e.value.field == "radio.wall_dB" and e.value.line == 3


# ----- coverage --------------------------------------------------------------------------------------------------
def test_the_fan_of_rays_counts_the_same_walls_as_the_line_of_sight(building):
    grid = Site(str(building.resolve())).grid()
    rng = np.random.default_rng(5)
    north, east = rng.uniform(3, 21, 300), rng.uniform(1, 45, 300)
    station = (site_maps.STATION[1], site_maps.STATION[0])
    runs, metres = coverage.wall_counts(grid, station, north, east, 0.25)
    exact = [grid.crossed(station, (n, e)) for n, e in zip(north, east, strict=True)]
    agree = np.mean([r == x[0] for r, x in zip(runs.tolist(), exact, strict=True)])
    assert agree >= 0.95  # a ray a quarter cell off may graze a wall's end the exact line misses
    assert np.median(np.abs(metres - np.array([x[1] for x in exact]))) <= 0.1


def test_unknown_specks_inside_free_space_are_floor_and_other_unknown_cells_walls(tmp_path):
    cells = np.full((40, 40), site_maps.FREE, dtype=np.uint8)
    cells[:, :2] = site_maps.UNKNOWN  # the unmapped outside, at the map's edge
    cells[10:12, 10:12] = site_maps.UNKNOWN  # a speck between two laser rays: 1 m2 at 0.5 m cells is not small
    cells[20, 20] = site_maps.UNKNOWN  # 0.25 m2, enclosed by free cells: floor
    cells[30, 30] = site_maps.UNKNOWN
    cells[30, 31] = site_maps.OCCUPIED  # beside an occupied cell: part of a wall's unseen inside
    grid = Site(str(write_map(tmp_path, cells))).grid()
    solid = grid.solid[::-1]  # image order again
    assert not solid[20, 20]
    assert solid[10, 10] and solid[30, 30] and solid[5, 0]
