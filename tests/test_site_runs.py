"""Your own site, flown (docs/architecture.md §7.2): `sim run map:...` passes its criteria and repeats exactly,
`sim world map:...` writes a world.toml that flies the same run, bad input exits 2 naming the file and field,
`site survey` writes the coverage over the map, and `site fit` gives back the radio parameters a run was flown
with, within the uncertainty it prints."""

from __future__ import annotations

import csv
import json
import sys

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import numpy as np
import pytest

from sim.cli import main
from tests import site_maps

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def building(tmp_path_factory):
    return site_maps.building(tmp_path_factory.mktemp("building"))


STATION = f"{site_maps.STATION[0]},{site_maps.STATION[1]}"


def metrics(out) -> dict:
    m = json.loads((out / "metrics.json").read_text())
    m.pop("real_time_factor")
    return m


def test_a_map_world_flies_passes_and_repeats_and_its_world_file_flies_the_same(building, tmp_path):
    args = ["sim", "run", f"map:{building}", "--station", STATION, "--seed", "2", "--quiet", "--no-plots"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    first = metrics(tmp_path / "a")
    assert first["passed"] and first["collisions"] == 0 and first["regained_by"] == "return"
    assert first["link_lost_s"] is not None and first["link_regained_s"] is not None
    assert main([*args, "--out", str(tmp_path / "b")]) == 0
    assert metrics(tmp_path / "b") == first
    assert main(["sim", "world", f"map:{building}", "--station", STATION, "--seed", "2",
                 "--out", str(tmp_path / "w")]) == 0
    assert (tmp_path / "w" / "world.png").is_file()
    assert main(["sim", "run", str(tmp_path / "w" / "world.toml"), "--seed", "2", "--quiet", "--no-plots",
                 "--out", str(tmp_path / "c")]) == 0
    again = metrics(tmp_path / "c")
    assert {k: v for k, v in again.items() if k != "scenario"} == {k: v for k, v in first.items() if k != "scenario"}


@pytest.mark.parametrize(("extra", "says"), [
    ([], "station"),
    (["--station", "100,12"], "off the map"),
    (["--station", "0.05,2.1"], "occupied"),
])
def test_a_map_world_without_a_good_station_exits_2_naming_it(building, tmp_path, capsys, extra, says):
    with pytest.raises(SystemExit) as e:
        main(["sim", "world", f"map:{building}", *extra, "--out", str(tmp_path / "w")])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err


def test_a_broken_map_exits_2_naming_the_file_and_field(tmp_path, capsys):
    site_maps.write_pgm(tmp_path / "m.pgm", np.full((4, 4), 254, dtype=np.uint8))
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.1\nfree_thresh: 2\n")
    for cmd in (["sim", "world", f"map:{tmp_path / 'm.yaml'}", "--station", "0.2,0.2", "--out", str(tmp_path / "o")],
                ["site", "survey", str(tmp_path / "m.yaml"), "--station", "0.2,0.2", "--out", str(tmp_path / "s")]):
        with pytest.raises(SystemExit) as e:
            main(cmd)
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert "m.yaml:3: free_thresh" in err


def test_site_survey_writes_the_predicted_coverage_over_the_map(building, tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["site", "survey", str(building), "--station", STATION, "--out", str(out)]) == 0
    assert "frontier" in capsys.readouterr().out
    with (out / "coverage.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["x", "y", "rssi_dbm", "delivery"]
    x = np.array([float(r["x"]) for r in rows])
    y = np.array([float(r["y"]) for r in rows])
    delivery = np.array([float(r["delivery"]) for r in rows])
    near = np.hypot(x - site_maps.STATION[0], y - site_maps.STATION[1]) < 3.0
    assert delivery[near].min() > 0.99  # beside the station (map frame: x east, y north)
    assert delivery.min() < 0.01  # and dead behind the far rooms' walls
    assert x.min() >= 0 and x.max() <= 48 and y.min() >= 0 and y.max() <= 24  # the map frame, in metres
    assert (out / "coverage.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_site_fit_gives_back_the_parameters_a_run_was_flown_with(building, tmp_path, capsys):
    flown = {"ref_loss_db": 40.0, "exponent": 2.2, "wall_db": 8.0, "wall_db_per_m": 4.0, "shadowing_db": 3.0}
    (tmp_path / "r.toml").write_text("[radio]\n" + "".join(f"{k} = {v}\n" for k, v in flown.items()))
    run = tmp_path / "run"
    assert main(["sim", "run", f"map:{building}", "--station", STATION, "--seed", "1", "--radio",
                 str(tmp_path / "r.toml"), "--quiet", "--no-plots", "--out", str(run)]) == 0
    capsys.readouterr()
    assert main(["site", "fit", str(building), "--station", STATION, "--tlog", str(run / "run.tlog"),
                 "--out", str(tmp_path / "fit")]) == 0
    printed = capsys.readouterr().out
    got = tomllib.loads((tmp_path / "fit" / "radio.toml").read_text())["radio"]
    text = (tmp_path / "fit" / "radio.toml").read_text()
    for name in ("ref_loss_db", "exponent", "wall_db", "wall_db_per_m"):
        line = next(ln for ln in text.splitlines() if ln.startswith(name))
        se = float(line.split("+-")[1])
        assert abs(got[name] - flown[name]) <= 2 * se, (name, got[name], se)  # within the printed uncertainty
        assert name in printed
    assert abs(got["shadowing_db"] - flown["shadowing_db"]) < 1.5
    # the fitted table is what --radio takes
    assert main(["sim", "world", f"map:{building}", "--station", STATION, "--radio",
                 str(tmp_path / "fit" / "radio.toml"), "--out", str(tmp_path / "w")]) == 0


def test_site_fit_of_a_log_without_positions_exits_2(building, tmp_path, capsys):
    (tmp_path / "empty.tlog").write_bytes(b"")
    with pytest.raises(SystemExit) as e:
        main(["site", "fit", str(building), "--station", STATION, "--tlog", str(tmp_path / "empty.tlog"),
              "--out", str(tmp_path / "f")])
    assert e.value.code == 2
    assert "no positions" in capsys.readouterr().err
