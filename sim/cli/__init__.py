"""The ``returnlink`` command line: one entry point for the simulator, the ground station and set-up helpers.

One module per sub-command (``sim.cli.run``, ``sim.cli.sweep``, ``sim.cli.serve``, ...), each adding its own parser
and holding its own command; what they share is in ``sim.cli.common``. Bad arguments exit with code 2 and a message
naming the problem (argparse's convention).
"""

from __future__ import annotations

import argparse

from sim.cli import demo, dialect, keys, run, serve, site, sweep, world
from sim.cli.common import Refusal, usage_error


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="returnlink", description="Lease-based automated return to link for MAVLink robots.")
    sub = p.add_subparsers(dest="command", required=True)
    dialect.add_parser(sub)
    demo.add_parser(sub)
    sim = sub.add_parser("sim", help="the simulator").add_subparsers(dest="sim_command", required=True)
    for command in (run, sweep, world):
        command.add_parser(sim)
    site.add_parser(sub)
    serve.add_parser(sim)
    keys.add_parser(sub)
    from gcs import cli as gcs_cli

    gcs_cli.add_parser(sub)
    from vehicle.companion import cli as companion_cli

    companion_cli.add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except Refusal as e:
        return usage_error(str(e))
