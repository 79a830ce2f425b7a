"""``returnlink gcs ...``: the ground station from a shell. Every failure prints what went wrong and exits 1
(2 for bad arguments or files).

The commands themselves are the table in ``gcs/commands.py``; this module adds the connection options, the
long-lived ``shell`` and ``map`` sessions, and the one-shot run: connect, run one command from the table, leave.
"""

from __future__ import annotations

import argparse
import os
import sys

from gcs.commands import Context, UsageError, add_commands, execute, find
from link import args as types


def add_parser(sub) -> None:
    g = sub.add_parser("gcs", help="talk to a returnlink vehicle as a ground station")
    g.add_argument("--url", type=types.url, default="udpin:127.0.0.1:14550",
                   help="udpin:HOST:PORT or udpout:HOST:PORT")
    g.add_argument("--sysid", type=types.SYSID, default=255, help="this ground station's MAVLink system id")
    g.add_argument("--compid", type=types.COMPID, default=190, help="this ground station's component id")
    g.add_argument("--target", type=types.SYSID, default=1, help="the vehicle's system id")
    g.add_argument("--target-comp", type=types.COMPID, default=1,
                   help="the component addressed: 1, or 191 for returnlink running as a companion (leases, plans)")
    g.add_argument("--timeout", type=types.SECONDS, default=10.0, help="seconds to wait for the vehicle")
    g.add_argument("--key", help="signing key file (64 hex characters): sign everything, believe only the "
                   "vehicle's signed frames")
    gs = g.add_subparsers(dest="gcs_command", required=True)
    add_commands(gs, "oneshot")
    sh = gs.add_parser("shell", help="one long-lived station at a prompt (or commands from a pipe or file)")
    sh.set_defaults(command_path="shell")
    m = gs.add_parser("map", help="a live map in the browser, served on 127.0.0.1")
    m.add_argument("--port", type=types.LISTEN_PORT, default=8080, help="HTTP port on 127.0.0.1 (0: any free port)")
    m.add_argument("--linkmap", metavar="FILE", help="draw the link layer from this linkmap.csv (re-read on every "
                   "refresh; e.g. the one a `sim run` wrote) instead of fetching the vehicle's over MAVLink FTP")
    m.set_defaults(command_path="map")
    g.set_defaults(func=run)


def _open_client(args: argparse.Namespace):
    """The client for the parsed connection options; a bad --url is a usage error (exit 2)."""
    from gcs.client import Client, GcsError, parse_url

    try:
        parse_url(args.url)
    except GcsError as e:
        raise UsageError(f"--url: {e}") from None
    key = _signing_key(args)
    return Client(args.url, args.sysid, args.compid, target=args.target, key=key, target_comp=args.target_comp)


def _signing_key(args: argparse.Namespace):
    """The key of ``--key FILE`` where that option exists (docs/architecture.md §4.1); a damaged or missing file is a
    usage error naming the file and line, reported before any link opens."""
    path = getattr(args, "key", None)
    if not path:
        return None
    from link.signing import KeyFileError, load_key

    try:
        return load_key(path)
    except KeyFileError as e:
        raise UsageError(f"key file {e}") from None


def _quiet_broken_pipe() -> int:
    """The reader of our stdout went away (``| head``): stop quietly, and keep Python from complaining when it
    flushes stdout at exit."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 0


def run(args: argparse.Namespace) -> int:
    try:
        return _run(args)
    except BrokenPipeError:
        return _quiet_broken_pipe()
    except UsageError as e:
        print(f"returnlink gcs: error: {e}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    from gcs.client import GcsError

    path = args.command_path
    command = None if path in ("shell", "map") else find(path)
    if command is not None and not command.vehicle:
        return execute(Context(None, sys.stdout), args)  # type: ignore[arg-type] - needs no vehicle
    if command is not None:
        command.check(args, False)  # a bad plan file or a drive without SECONDS: exit 2 before any link opens
    try:
        with _open_client(args) as c:
            c.connect(args.timeout)
            if path == "shell":
                from gcs.shell import run_shell

                return run_shell(c)
            if path == "map":
                from pathlib import Path

                from gcs.linkmap_layer import VehicleSource, file_source
                from gcs.mapserver import serve_map

                source = file_source(Path(args.linkmap)) if args.linkmap else VehicleSource(c.gs)
                return serve_map(c, args.port, source)
            return execute(Context(c, sys.stdout), args)
    except GcsError as e:
        print(f"returnlink gcs: {e}", file=sys.stderr)
        return 1
