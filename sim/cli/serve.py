"""``returnlink sim serve``: a scenario in real time over UDP for MAVSDK, MAVProxy and QGroundControl, with
returnlink's own vehicle aboard; ``--vehicle ardurover|px4rover`` hands over to ``sim.cli.serve_autopilot``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from link import args as types
from sim.cli import serve_autopilot
from sim.cli.common import (
    DEFAULT_PEERS,
    Refusal,
    add_firmware_option,
    add_map_options,
    add_px4_option,
    fail,
    parm_file,
    scenario,
    serve_state,
    serving_line,
    warn_heartbeat_speedup,
    writable_dir,
)


def add_parser(sim) -> None:
    from sim.registry import VEHICLES, autopilot_policies

    serve = sim.add_parser("serve", help="run a scenario in real time over UDP for MAVSDK, MAVProxy, QGC")
    serve.add_argument("scenario", help="a built-in scenario name, gen:KIND (drawn from --seed) or a .toml file")
    serve.add_argument("--vehicle", choices=VEHICLES,
                       help="robot model (default: the scenario's); ardurover: the real ArduPilot firmware; "
                            "px4rover: the real PX4 rover")
    serve.add_argument("--policy", choices=autopilot_policies(),
                       help="with --vehicle ardurover: its GCS failsafe (default ardupilot-smartrtl), companion: "
                            "returnlink companion on its telemetry port (--params, --key, --state configure it), or "
                            "applet: returnlink's Lua applet aboard the firmware (its RLNK_ parameters over MAVLink); "
                            "with --vehicle px4rover: px4-hold or px4-return (default), PX4's data-link failsafe, or "
                            "companion")
    add_firmware_option(serve)
    add_px4_option(serve)
    add_map_options(serve)
    serve.add_argument("--seed", type=types.SEED)
    serve.add_argument("--speedup", type=types.SPEEDUP, default=1.0, help="run K times faster than real time")
    serve.add_argument("--port", type=types.LISTEN_PORT, default=14580, help="UDP port the vehicle listens on")
    serve.add_argument("--peer", type=types.address, action="append",
                       help="HOST:PORT to send to before anyone talks (default 127.0.0.1:14550 and :14540)")
    serve.add_argument("--perfect-link", action="store_true", help="no radio model: every packet arrives")
    serve.add_argument("--duration", type=types.SECONDS_OR_INF, default=float("inf"),
                       help="stop after this many simulated s")
    serve.add_argument("--params", help=".parm file to boot from and save parameter changes to")
    serve.add_argument("--state", help="directory for the epochs kept across restarts (default: beside --params, "
                                       "else $XDG_STATE_HOME/returnlink)")
    serve.add_argument("--out", help="where to write the plot on exit")
    serve.add_argument("--key", help="signing key file (returnlink keys new): sign everything, obey only signed "
                       "frames; its timestamp is kept in FILE.stamp")
    serve.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    from sim.registry import AUTOPILOT_VEHICLES, Outside, needing, outside

    sc = scenario(args.scenario, args.seed, args)
    if args.px4 and outside(args.vehicle) is not Outside.PX4:
        raise fail(f"--px4 goes with --vehicle {' or '.join(needing(Outside.PX4))} (got vehicle "
                   f"{args.vehicle or sc.vehicle})")
    if args.vehicle in AUTOPILOT_VEHICLES:
        return serve_autopilot.command(args, sc, args.vehicle)
    if args.policy or args.firmware:
        raise fail(f"--policy and --firmware go with --vehicle {' or '.join(AUTOPILOT_VEHICLES)} (the native vehicle "
                   "flies its own plan)")
    params = parm_file(args.params)
    if args.out:
        writable_dir(Path(args.out))  # the plot is written on exit: know now that it can be
    peers = tuple(args.peer) if args.peer else DEFAULT_PEERS
    keystore, epochs = serve_state(args)
    server = _server(args, sc, peers, params, keystore, epochs)
    warn_heartbeat_speedup(args.speedup, server.vehicle.params["LNK_TIMEOUT"], "vehicle")
    host, port = server.address
    print(f"returnlink: {sc.name} ({server.kind}) on udp {host}:{port}, sending to "
          + serving_line(peers, args.perfect_link)
          + ("" if keystore is None else f"; signing with key {keystore.key.fingerprint} from {keystore.path}"),
          file=sys.stderr, flush=True)
    try:
        server.serve(args.speedup, args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
        _plot(server, args, sc)
    return 0


def _server(args: argparse.Namespace, sc, peers, params, keystore, epochs):
    """The real-time server, bound; a damaged kept file or a port in use: a Refusal (exit 2)."""
    from link.storage import StoredFileError
    from sim.serve import Server

    try:
        return Server(sc, args.vehicle, args.seed, args.port, peers, args.perfect_link, params, keystore, epochs)
    except StoredFileError as e:  # a damaged kept file: refuse to start rather than boot on defaults
        raise Refusal(str(e)) from None
    except OSError as e:
        raise Refusal(f"cannot bind 127.0.0.1:{args.port}: {e}") from None


def _plot(server, args: argparse.Namespace, sc) -> None:
    """The served run's trajectory, written on exit (--out, else out/serve-SCENARIO-VEHICLE)."""
    from sim.report import trajectory

    out = Path(args.out) if args.out else Path("out") / f"serve-{sc.name}-{server.kind}"
    try:
        print(f"returnlink: wrote {trajectory(server, out / 'trajectory.png')}", file=sys.stderr)
    except OSError as e:
        raise fail(f"cannot write the plot to {out}: {e}") from None
