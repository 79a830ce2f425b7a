"""``returnlink site survey|fit``: your own site, a ROS map_server map as the world (docs/site.md): the predicted
coverage from a station and a campaign of returns beyond it, or the radio model fitted to a real drive's log."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from link import args as types
from sim.cli import sweep
from sim.cli.common import add_firmware_option, fail, print_wrote, usage_error, writable_dir


def add_parser(sub) -> None:
    site = sub.add_parser("site", help="your own site: a ROS map_server map as the world (docs/site.md)")
    cmds = site.add_subparsers(dest="site_command", required=True)
    _add_survey_parser(cmds)
    _add_fit_parser(cmds)


def _add_survey_parser(cmds) -> None:
    sv = cmds.add_parser("survey", help="predicted coverage over the map, and a campaign of returns beyond it")
    sv.add_argument("map", help="the map_server YAML (image, resolution, origin, ...)")
    sv.add_argument("--station", type=types.STATION, required=True, metavar="X,Y",
                    help="where the ground station stands (map frame, metres: x east, y north)")
    sv.add_argument("--out", required=True, help="directory for coverage.csv, coverage.png and the campaign")
    sv.add_argument("--radio", metavar="FILE", help="a [radio] table (returnlink site fit writes one)")
    sv.add_argument("--power-dbm", type=float, default=20.0, help="the station's transmit power (default 20 dBm)")
    sv.add_argument("--trials", type=int, help="also fly a campaign: returns to this many goals beyond coverage "
                                               "(each seed draws one), every policy and robot")
    sv.add_argument("--policies", default="returnlink,backup,smartrtl",
                    help="the campaign's policies (default returnlink,backup,smartrtl)")
    sv.add_argument("--vehicles", default="rover,legged", help="the campaign's robots (default rover,legged)")
    sv.add_argument("--workers", type=int, help="trials at a time (default: every CPU)")
    sv.add_argument("--quiet", action="store_true", help="no progress bar")
    add_firmware_option(sv)
    sv.set_defaults(func=survey_command)


def _add_fit_parser(cmds) -> None:
    fit = cmds.add_parser("fit", help="fit the radio model to a real drive's .tlog")
    fit.add_argument("map", help="the map_server YAML the drive was made in")
    fit.add_argument("--station", type=types.STATION, required=True, metavar="X,Y",
                     help="where the ground station stood (map frame, metres: x east, y north)")
    fit.add_argument("--tlog", required=True, help="the drive's MAVLink log (.tlog)")
    fit.add_argument("--out", required=True, help="directory for radio.toml and the fit's plot")
    fit.add_argument("--anchor", type=types.point("anchor"), metavar="LAT,LON",
                     help="the map origin's latitude and longitude, to place GLOBAL_POSITION_INT on the map")
    fit.add_argument("--power-dbm", type=float, default=20.0, help="the station's transmit power (default 20 dBm)")
    fit.set_defaults(func=fit_command)


def _site_world(args: argparse.Namespace):
    """The map, site, station and radio of a `site` command's YAML, --station and --radio; exit 2 naming the
    file and field when any is bad."""
    from sim.maps import mapfile
    from sim.maps.grid import Site
    from sim.scenario import STATION_POWER_DBM, ScenarioError, read_radio_file
    from sim.world import Station

    try:
        occupancy = mapfile.read(args.map)
        model, loss = read_radio_file(args.radio) if args.radio else ({}, {})
    except (mapfile.MapError, ScenarioError) as e:
        raise fail(str(e)) from None
    from dataclasses import replace

    from link.radio import RadioParams

    site = replace(Site(str(Path(args.map).resolve()), digest=occupancy.digest), **loss)
    x, y = args.station
    power = getattr(args, "power_dbm", 20.0)
    if not STATION_POWER_DBM[0] <= power <= STATION_POWER_DBM[1]:
        raise fail(f"--power-dbm must be within {STATION_POWER_DBM[0]:g}..{STATION_POWER_DBM[1]:g}, got {power:g}")
    station = Station("gcs", y, x, 255, power)
    grid = site.grid()
    problem = grid.station_problem(station.x, station.y)
    if problem:
        raise fail(f"{args.map}: station: the station at x {x:g}, y {y:g} (map frame) {problem}")
    return site, grid, station, replace(RadioParams(), **model), {**model, **loss}


def survey_command(args: argparse.Namespace) -> int:
    """`site survey`: the predicted coverage, and with --trials a campaign of returns beyond it."""
    from link.storage import write_atomic
    from sim.maps import survey

    if args.trials is not None and not 1 <= args.trials <= 1000:
        return usage_error(f"--trials must be within 1..1000, got {args.trials}")
    policies = [p.strip() for p in args.policies.split(",") if p.strip()]
    vehicles = [v.strip() for v in args.vehicles.split(",") if v.strip()]
    out = Path(args.out)
    writable_dir(out)
    site, grid, station, radio, radio_table = _site_world(args)
    print(f"returnlink: surveying {args.map} ({grid.cols} x {grid.rows} cells at {grid.res:g} m) from the station "
          f"at x {args.station[0]:g}, y {args.station[1]:g}", file=sys.stderr)
    s = survey.survey(grid, site, station, radio)
    try:
        paths = [survey.write_csv(s, out / "coverage.csv"),
                 survey.draw(s, grid, station, out / "coverage.png",
                             f"{Path(args.map).name}: predicted coverage from the station (walls {site.wall_db:g} dB "
                             f"a crossing + {site.wall_db_per_m:g} dB/m, exponent {radio.exponent:g})")]
    except OSError as e:
        raise fail(f"cannot write the survey to {out}: {e}") from None
    print(f"returnlink: {args.map}")
    for line in survey.summary_lines(s):
        print(line)
    print_wrote(paths)
    if args.trials is None:
        return 0
    name = f"site:{Path(args.map).stem}"
    write_atomic(out / "site.toml", survey.site_scenario(Path(args.map), args.station, radio_table, name).encode())
    write_atomic(out / "campaign.toml", survey.campaign_spec(args.trials, policies, vehicles).encode())
    sweep_args = argparse.Namespace(spec=str(out / "campaign.toml"), out=str(out), workers=args.workers,
                                    address=None, quiet=args.quiet, firmware=args.firmware, px4=None)
    return sweep.command(sweep_args)


def fit_command(args: argparse.Namespace) -> int:
    """`site fit`: the radio model's parameters from a logged drive, with their uncertainty."""
    from sim.maps import fit

    out = Path(args.out)
    writable_dir(out)
    site, grid, station, radio, _ = _site_world(argparse.Namespace(**{**vars(args), "radio": None}))
    try:
        samples = fit.samples_from_tlog(Path(args.tlog), grid, site, station, args.anchor)
        result = fit.fit(samples, radio, station.power_dbm)
    except fit.FitError as e:
        raise fail(str(e)) from None
    try:
        paths = fit.write(result, samples, out)
    except OSError as e:
        raise fail(f"cannot write the fit to {out}: {e}") from None
    for line in fit.report_lines(result, samples):
        print(line)
    print_wrote(paths)
    return 0
