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


def _scenario(name: str):
    from sim.scenario import ScenarioError, load

    try:
        return load(name)
    except (ScenarioError, OSError) as e:
        print(f"returnlink: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None


def _cmd_sim_run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from sim import metrics, report
    from sim.runner import Run, write_metrics, write_tlog

    sc = _scenario(args.scenario)
    kind = args.vehicle or sc.vehicle
    seed = sc.seed if args.seed is None else args.seed
    out = Path(args.out) if args.out else Path("out") / f"{sc.name}-{kind}-{seed}"
    print(f"returnlink: running {sc.name} with the {kind} (seed {seed}, policy {args.policy}), "
          f"{sc.duration:g} simulated s", file=sys.stderr)
    run = Run(sc, kind, seed, progress=not args.quiet, policy=args.policy).run()
    m = run.metrics = metrics.compute(run)
    paths = [write_metrics(m, out / "metrics.json"), write_tlog(run, out / "run.tlog"),
             report.trajectory(run, out / "trajectory.png"), report.timeline(run, out / "timeline.png")]
    print(metrics.summary(run, m))
    print("  wrote " + ", ".join(str(p) for p in paths))
    return 0 if m["passed"] else 1


def _address(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    try:
        return host or "127.0.0.1", int(port)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT") from None


def _cmd_sim_serve(args: argparse.Namespace) -> int:
    from pathlib import Path

    from sim.serve import Server

    sc = _scenario(args.scenario)
    if args.speedup <= 0:
        print("returnlink: error: --speedup must be positive", file=sys.stderr)
        return 2
    peers = tuple(args.peer) if args.peer else (("127.0.0.1", 14550), ("127.0.0.1", 14540))
    try:
        server = Server(sc, args.vehicle, args.seed, args.port, peers, args.perfect_link,
                        Path(args.params) if args.params else None)
    except OSError as e:
        print(f"returnlink: error: cannot bind 127.0.0.1:{args.port}: {e}", file=sys.stderr)
        return 2
    timeout = server.vehicle.params["LNK_TIMEOUT"]
    if args.speedup > 1 and args.speedup >= timeout / 1.5:
        print(f"returnlink: warning: ground stations send a heartbeat once a wall-clock second, which at --speedup "
              f"{args.speedup:g} is once every {args.speedup:g} simulated s; with LNK_TIMEOUT {timeout:g} s the "
              f"vehicle will think an idle station lost. Raise LNK_TIMEOUT or lower --speedup.", file=sys.stderr)
    host, port = server.address
    print(f"returnlink: {sc.name} ({server.kind}) on udp {host}:{port}, sending to "
          + ", ".join(f"{h}:{p}" for h, p in peers) + ("" if args.perfect_link else ", through the radio model"),
          file=sys.stderr, flush=True)
    try:
        server.serve(args.speedup, args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
        out = Path(args.out) if args.out else Path("out") / f"serve-{sc.name}-{server.kind}"
        print(f"returnlink: wrote {server.plot(out / 'trajectory.png')}", file=sys.stderr)
    return 0


def build_parser() -> argparse.ArgumentParser:
    from sim.policies import DEFAULT_POLICY, POLICY_NAMES

    p = argparse.ArgumentParser(
        prog="returnlink", description="Lease-based automated return to link for MAVLink robots.")
    sub = p.add_subparsers(dest="command", required=True)
    d = sub.add_parser("dialect", help="the returnlink MAVLink dialect")
    d.add_argument("action", choices=["install", "path"], help="install: generate and register the pymavlink module")
    d.set_defaults(func=_cmd_dialect)
    demo = sub.add_parser("demo", help="the FIG. 2-3 lease sequence, printed from the real lease code")
    demo.set_defaults(func=_cmd_demo)
    sim = sub.add_parser("sim", help="the simulator").add_subparsers(dest="sim_command", required=True)
    run = sim.add_parser("run", help="run a scenario in lockstep, as fast as possible")
    run.add_argument("scenario", help="a built-in scenario name or a .toml file")
    run.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    run.add_argument("--vehicle", choices=["rover", "legged"], help="robot model (default: the scenario's)")
    run.add_argument("--out", help="output directory (default: out/SCENARIO-VEHICLE-SEED)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--policy", choices=POLICY_NAMES, default=DEFAULT_POLICY,
                     help="what the vehicle does when its link is lost: the scenario's plan (returnlink) or a "
                          "baseline (DESIGN §9)")
    run.set_defaults(func=_cmd_sim_run)
    serve = sim.add_parser("serve", help="run a scenario in real time over UDP for MAVSDK, MAVProxy, QGC")
    serve.add_argument("scenario", help="a built-in scenario name or a .toml file")
    serve.add_argument("--vehicle", choices=["rover", "legged"], help="robot model (default: the scenario's)")
    serve.add_argument("--seed", type=int)
    serve.add_argument("--speedup", type=float, default=1.0, help="run K times faster than real time")
    serve.add_argument("--port", type=int, default=14580, help="UDP port the vehicle listens on")
    serve.add_argument("--peer", type=_address, action="append",
                       help="HOST:PORT to send to before anyone talks (default 127.0.0.1:14550 and :14540)")
    serve.add_argument("--perfect-link", action="store_true", help="no radio model: every packet arrives")
    serve.add_argument("--duration", type=float, default=float("inf"), help="stop after this many simulated s")
    serve.add_argument("--params", help=".parm file to boot from and save parameter changes to")
    serve.add_argument("--out", help="where to write the plot on exit")
    serve.set_defaults(func=_cmd_sim_serve)
    from gcs import cli as gcs_cli

    gcs_cli.add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
