"""``returnlink demo``: the patent's FIG. 2-3 lease sequence, printed from the real lease code."""

from __future__ import annotations

import argparse


def add_parser(sub) -> None:
    demo = sub.add_parser("demo", help="the FIG. 2-3 lease sequence, printed from the real lease code")
    demo.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    from sim import fig_demo

    fig_demo.run()
    return 0
