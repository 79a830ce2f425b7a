"""The ``returnlink`` command line: one entry point for the simulator, the ground station and set-up helpers.

Bad arguments exit with code 2 and a message naming the problem (argparse's convention).
"""

from __future__ import annotations

import argparse
import sys


def _cmd_dialect(args: argparse.Namespace) -> int:
    from link import dialect

    if args.action == "install":
        print(f"returnlink dialect: {dialect.install()}")
    else:
        print(dialect.XML_PATH)
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from sim import fig_demo

    fig_demo.run()
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="returnlink", description="Lease-based automated return to link for MAVLink robots.")
    sub = p.add_subparsers(dest="command", required=True)
    d = sub.add_parser("dialect", help="the returnlink MAVLink dialect")
    d.add_argument("action", choices=["install", "path"], help="install: generate and register the pymavlink module")
    d.set_defaults(func=_cmd_dialect)
    demo = sub.add_parser("demo", help="the default demonstration")
    demo.set_defaults(func=_cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
