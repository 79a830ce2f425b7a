"""``returnlink sim world``: a scenario's map drawn (world.png) and the world written out as an ordinary scenario
file (world.toml), generated ones (gen:KIND) included, with the validity check's verdict."""

from __future__ import annotations

import argparse

from link import args as types
from sim.cli.common import add_map_options, fail, scenario_world, writable_dir


def add_parser(sim) -> None:
    w = sim.add_parser("world", help="draw a scenario's map and write it out as a scenario file (gen:KIND too)")
    w.add_argument("scenario", help="a built-in scenario, gen:office, gen:mine, gen:culvert, map:PATH.yaml (with "
                                    "--station), or a .toml file")
    w.add_argument("--seed", type=types.SEED, help="the seed that picks a generated world (default: the scenario's)")
    w.add_argument("--out", required=True, help="directory for world.png and world.toml")
    add_map_options(w)
    w.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    """`sim world`: a scenario's map (world.png) and the world as an ordinary scenario file (world.toml)."""
    from pathlib import Path

    from link.storage import write_atomic
    from sim.worlds.render import render
    from sim.worlds.toml_out import to_toml

    sc, redraws = scenario_world(args.scenario, args.seed, announce=False, args=args)
    out = Path(args.out)
    writable_dir(out)
    verdict = _verdict(sc)
    try:
        write_atomic(out / "world.toml", to_toml(sc).encode("utf-8"))
        png = render(sc, out / "world.png", verdict)
    except OSError as e:
        raise fail(f"cannot write the world to {out}: {e}") from None
    drawn = "not generated" if redraws is None else f"{redraws} draw{'' if redraws == 1 else 's'} redrawn"
    print(f"returnlink: {sc.name}, seed {sc.seed}: {drawn}")
    print(f"  {sc.description}")
    print(f"  route {verdict.clearance_m:.2f} m from the nearest wall; link {verdict.start_margin_db:.1f} dB over "
          f"the threshold at the start, " + ("dies at " + ", ".join(f"{c:.1f}" for c in verdict.dead_at)
                                             if verdict.dead_at else "never dies") + " (north, east; mean radio)")
    for problem in verdict.problems:  # a generated world never has one; a hand-drawn one may
        print(f"  fails the generated worlds' validity check: {problem}")
    print(f"  wrote {png}, {out / 'world.toml'}")
    return 0


def _verdict(sc):
    """The generated worlds' validity check of ``sc``; a map world's walls are its cells, so its route's clearance
    comes from the map."""
    from sim.worlds.check import check

    verdict = check(sc)
    if sc.site is None:
        return verdict
    from dataclasses import replace

    from sim.worlds.map_routes import route_clearance

    return replace(verdict, clearance_m=route_clearance(sc))
