"""``returnlink sim run --replay DIR TRIAL``: a stored campaign trial run again from its parquet row's inputs; its
metrics must come out the same (a real autopilot's within its repeatability)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sim.cli.common import Refusal, autopilot_path, print_wrote, usage_error

# the trial's inputs, which the comparison of its outcome leaves aside
_INPUTS = ("scenario", "vehicle", "seed", "policy")


def command(args: argparse.Namespace) -> int:
    """Run a stored campaign trial again from its parquet row's inputs; its metrics must come out the same."""
    from sim import outputs
    from sim.campaign.trial import simulate, trial_from_row

    if args.scenario or args.param or args.plan is not None or args.seed is not None or args.vehicle:
        return usage_error("--replay takes every input from the stored trial; give no SCENARIO, --seed, "
                           "--vehicle, --param or --plan with it")
    directory, wanted = args.replay
    try:
        row = _stored_row(Path(directory), wanted)
    except Refusal as e:
        return usage_error(str(e))
    trial = _with_autopilot(trial_from_row(row), args)
    out = Path(args.out) if args.out else Path(directory) / "replay" / row["trial_id"]
    print(f"returnlink: replaying trial {row['trial_id']}: {trial.scenario} with the {trial.vehicle} (seed "
          f"{trial.seed}, policy {trial.policy}, params {row['params']})", file=sys.stderr)
    try:
        run = simulate(trial, progress=not args.quiet)
    except Exception as e:  # noqa: BLE001 - an error row replayed: say what it raised, as the campaign did
        print(f"returnlink: the trial raised {type(e).__name__}: {e} (stored: {row.get('error')})", file=sys.stderr)
        return 1
    m = run.metrics
    paths = outputs.write(run, out, plots=not args.no_plots)
    print(outputs.summary(run, m))
    print_wrote(paths)
    if row["status"] == "error":
        print(f"returnlink: the stored row is an error ({row.get('error')}); nothing to compare", file=sys.stderr)
        return 0 if m["passed"] else 1
    return _compared(row, m, run.plant.repeatability)


def _stored_row(directory: Path, wanted: str) -> dict:
    """The one row of the campaign in ``directory`` whose trial id starts with ``wanted``; else a Refusal."""
    from link.storage import StoredFileError
    from sim.campaign.store import TRIALS_FILE, read_rows

    path = directory / TRIALS_FILE
    if not path.is_file():
        raise Refusal(f"{path}: no such campaign file (run `returnlink sim sweep SPEC --out {directory}`)")
    try:
        rows = read_rows(path)
    except StoredFileError as e:
        raise Refusal(str(e)) from None
    found = [r for r in rows if r["trial_id"].startswith(wanted)] if wanted else []
    if len(found) != 1:
        raise Refusal(f"{path}: {'no' if not found else 'more than one'} trial {wanted!r}")
    return found[0]


def _with_autopilot(trial, args: argparse.Namespace):
    """The trial with this machine's autopilot (--firmware, --px4 or their defaults) when it flies one: the stored
    row does not say where another machine kept its binary."""
    from dataclasses import replace

    binary = autopilot_path(args, trial.vehicle)
    return trial if binary is None else replace(trial, firmware=str(binary))


def _compared(row: dict, m: dict, within) -> int:
    """The exit code of a replay whose run completed: its metrics against the stored row's, as far as its plant
    repeats a run (``within``, ``sim.compare.Repeatability``). A returnlink vehicle must repeat them exactly; a real
    autopilot only within its repeatability, and beyond it is told, not failed."""
    import json

    from sim.campaign.store import JSON_METRICS
    from sim.compare import differing

    stored = {k: (json.loads(v) if isinstance(v, str) and k in JSON_METRICS else v)
              for k, v in row.items() if k in m}
    fresh = json.loads(json.dumps({k: m[k] for k in stored}))
    differ = [k for k in differing(stored, fresh, within) if k not in _INPUTS]
    if differ and not within.exact:
        print(f"returnlink: the firmware did not repeat the stored trial exactly: {', '.join(differ)} differ beyond "
              "its repeatability (see sim/firmware/metrics.py: ArduPilot SITL's own threads make a firmware run "
              "repeatable only within a tick or so, and the radio can turn that tick into another outcome)",
              file=sys.stderr)
        return 0 if m["passed"] else 1
    if differ:
        print(f"returnlink: error: replay differs from the stored trial in {', '.join(differ)}", file=sys.stderr)
        return 1
    print("  metrics identical to the stored trial (real_time_factor aside)" if within.exact else
          "  metrics match the stored trial within the firmware's repeatability (sim.firmware.metrics.TOLERANCE)")
    return 0 if m["passed"] else 1
