"""``returnlink sim sweep SPEC``: a campaign, a grid of trials on Ray (or one at a time), kept in a directory that
a second run resumes, with a summary and a report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sim.cli.common import add_firmware_option, add_px4_option, autopilot_path, usage_error


def add_parser(sim) -> None:
    sw = sim.add_parser("sweep", help="a campaign: a grid of trials on Ray, with a summary and a report")
    sw.add_argument("spec", help="campaign spec (.toml): scenarios, vehicles, seeds, params, policies, timeout_s")
    sw.add_argument("--out", help="campaign directory (default: out/sweep-SPEC); running again resumes it")
    sw.add_argument("--workers", type=int, help="trials at a time (default: every CPU of this machine or cluster)")
    sw.add_argument("--address", help="join a Ray cluster: auto or HOST:PORT (default: a local Ray, started here)")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    add_firmware_option(sw)
    add_px4_option(sw)
    sw.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    from sim.campaign.spec import SpecError, load_spec

    problem = _bad_workers_or_address(args)
    if problem:
        return usage_error(problem)
    try:
        spec = load_spec(args.spec)
    except SpecError as e:
        return usage_error(str(e))
    spec = _with_autopilots(spec, args)
    out = Path(args.out) if args.out else Path("out") / f"sweep-{Path(args.spec).stem}"
    from link.storage import StoredFileError
    from sim.campaign import sweep
    from sim.campaign.executors import RayExecutor, SerialExecutor

    try:
        store = sweep.Store(out)
    except StoredFileError as e:
        return usage_error(str(e))
    try:
        # a campaign already complete in DIR only rewrites its summary and report: no Ray to start
        executor = RayExecutor(args.workers, args.address) if store.pending(spec.trials) else SerialExecutor()
        with executor:
            done = sweep.run_sweep(spec, store, executor, progress=not args.quiet)
    except ConnectionError as e:
        return usage_error(f"cannot join Ray at {args.address}: {e}")
    except KeyboardInterrupt:
        print(f"returnlink: interrupted; finished trials are kept in {out} (run again to resume)", file=sys.stderr)
        return 130
    sweep.print_summary(done)
    return 0


def _bad_workers_or_address(args: argparse.Namespace) -> str | None:
    """What is wrong with --workers or --address, or None."""
    if args.workers is not None and args.workers < 1:
        return f"--workers must be at least 1, got {args.workers}"
    if args.address and args.address != "auto":
        host, _, port = args.address.rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            return f"--address must be auto or HOST:PORT, got {args.address!r}"
    return None


def _with_autopilots(spec, args: argparse.Namespace):
    """The spec with this machine's autopilot on every trial that flies one (exit 2 when it is not found), and
    the same autopilot in the environment for workers that run a stored trial again (a resumed or retried one)."""
    import os
    from dataclasses import replace

    from sim.registry import AUTOPILOT_VEHICLES, outside

    for vehicle in AUTOPILOT_VEHICLES:
        if any(t.vehicle == vehicle for t in spec.trials):
            binary = str(autopilot_path(args, vehicle))
            os.environ[outside(vehicle).env] = binary
            spec = replace(spec, trials=tuple(replace(t, firmware=binary) if t.vehicle == vehicle else t
                                              for t in spec.trials))
    return spec
