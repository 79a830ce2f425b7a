"""``returnlink dialect``: install or locate the returnlink MAVLink dialect."""

from __future__ import annotations

import argparse


def add_parser(sub) -> None:
    d = sub.add_parser("dialect", help="the returnlink MAVLink dialect")
    d.add_argument("action", choices=["install", "path"], help="install: generate and register the pymavlink module")
    d.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    from link import dialect

    if args.action == "install":
        print(f"returnlink dialect: {dialect.install()}")
    else:
        print(dialect.XML_PATH)
    return 0
