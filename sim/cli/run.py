"""``returnlink sim run``: one scenario in lockstep, as fast as possible, with any vehicle and policy; it leaves
its record, metrics and plots in a directory (``--replay`` runs a stored campaign trial again: ``sim.cli.replay``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from link import args as types
from sim.cli import replay
from sim.cli.common import (
    add_firmware_option,
    add_map_options,
    add_px4_option,
    autopilot_path,
    fail,
    policy_for,
    print_wrote,
    px4_unusable,
    scenario,
    usage_error,
    writable_dir,
)


def add_parser(sim) -> None:
    from sim.registry import DEFAULT_POLICY, POLICY_NAMES, VEHICLES

    run = sim.add_parser("run", help="run a scenario in lockstep, as fast as possible")
    run.add_argument("scenario", nargs="?", help="a built-in scenario name, gen:KIND (a world generated from the "
                                                "seed: gen:office, gen:mine, gen:culvert), map:PATH.yaml (a world "
                                                "made from a ROS map_server map, with --station) or a .toml file")
    run.add_argument("--seed", type=types.SEED, help="random seed (default: the scenario's)")
    run.add_argument("--vehicle", choices=VEHICLES,
                     help="robot model (default: the scenario's); ardurover: the scenario's rover driven by the real "
                          "ArduPilot firmware; px4rover: driven by the real PX4")
    run.add_argument("--out", help="output directory (default: out/SCENARIO-VEHICLE-SEED)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--policy", choices=POLICY_NAMES,
                     help=f"what the vehicle does when its link is lost: the scenario's plan ({DEFAULT_POLICY}, the "
                          "default), a baseline (docs/architecture.md §9), or with --vehicle ardurover the "
                          "firmware's own failsafe (default ardupilot-smartrtl) or companion: returnlink companion "
                          "between the radio and the firmware (§11); with --vehicle px4rover PX4's own data-link "
                          "failsafe: px4-hold or px4-return (the default; §10.1), or companion beside PX4 (§11.2)")
    add_firmware_option(run)
    add_px4_option(run)
    add_map_options(run)
    _add_campaign_options(run)
    run.set_defaults(func=command)


def _add_campaign_options(run) -> None:
    run.add_argument("--replay", nargs=2, metavar=("DIR", "TRIAL"),
                     help="run a campaign's trial again from DIR/trials.parquet (a unique id prefix will do)")
    run.add_argument("--param", type=param_assignment, action="append", metavar="NAME=VALUE",
                     help="set a vehicle parameter on top of the scenario's (repeatable)")
    run.add_argument("--plan", type=plan_spec, metavar="SPEC",
                     help="return plan instead of the scenario's, e.g. 'rtl:50 | loiter:30 | launch'")
    run.add_argument("--no-plots", action="store_true", help="skip trajectory.png and timeline.png")


def param_assignment(text: str) -> tuple[str, float]:
    """``NAME=VALUE`` for ``--param``, checked against the parameter table (name, number, range)."""
    from vehicle.params import ParamError, validate

    name, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=VALUE")
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: {value!r} is not a number") from None
    try:
        return name.strip(), validate(name.strip(), number)
    except ParamError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def plan_spec(text: str) -> tuple:
    """``--plan 'rtl:50 | loiter:30 | launch'`` (the ``gcs`` plan syntax) as the scenario's return plan; every
    item is checked against the one table of plan-item ranges (``link.plan_items``) on the way."""
    from gcs.plans import PlanError, parse_spec
    from vehicle.services.mission_transfer import Origin, to_plan

    try:
        return to_plan(tuple(parse_spec(text)), Origin())
    except (PlanError, ValueError) as e:
        raise argparse.ArgumentTypeError(f"--plan {text!r}: {e}") from None


def _run_overrides(sc, args: argparse.Namespace):
    """The scenario with ``--param`` values on top of its own and ``--plan`` instead of its return plan."""
    from dataclasses import replace

    if args.param:
        sc = replace(sc, params={**sc.params, **dict(args.param)})
    if args.plan is not None:
        sc = replace(sc, plan=args.plan)
    return sc


def command(args: argparse.Namespace) -> int:
    from sim import outputs

    if args.replay:
        return replay.command(args)
    if args.scenario is None:
        return usage_error("sim run needs a SCENARIO (or --replay DIR TRIAL)")
    sc = _run_overrides(scenario(args.scenario, args.seed, args), args)
    kind = args.vehicle or sc.vehicle
    policy = policy_for(args, kind)
    autopilot = _autopilot(args, kind)
    seed = sc.seed if args.seed is None else args.seed
    out = Path(args.out) if args.out else Path("out") / f"{sc.name.replace(':', '-')}-{kind}-{seed}"
    writable_dir(out)
    print(f"returnlink: running {sc.name} with the {kind} (seed {seed}, policy {policy}), "
          f"{sc.duration:g} simulated s", file=sys.stderr)
    from sim.runner import Run

    if autopilot is None:
        run = Run(sc, kind, seed, progress=not args.quiet, policy=policy).run()
    else:
        run = _run_autopilot(args, sc, kind, seed, policy, out, *autopilot)
        if isinstance(run, int):
            return run
    m = run.metrics = outputs.compute(run)
    try:
        paths = outputs.write(run, out, plots=not args.no_plots)
    except OSError as e:  # the directory was writable a moment ago: a full disk, a removed directory
        print(outputs.summary(run, m))
        raise fail(f"cannot write the results to {out}: {e}") from None
    print(outputs.summary(run, m))
    print_wrote(paths)
    return 0 if m["passed"] else 1


def _autopilot(args: argparse.Namespace, kind: str) -> tuple[Path, bool] | None:
    """The real autopilot a ``kind`` of vehicle runs (its binary or directory, and whether it is PX4), or None for
    a vehicle with returnlink aboard; --px4 with any other vehicle, or an autopilot not found: exit 2."""
    from sim.registry import Outside, needing, outside

    if args.px4 and outside(kind) is not Outside.PX4:
        raise fail(f"--px4 goes with --vehicle {' or '.join(needing(Outside.PX4))} (got vehicle {kind})")
    binary = autopilot_path(args, kind)
    return None if binary is None else (binary, outside(kind) is Outside.PX4)


def _run_autopilot(args: argparse.Namespace, sc, kind: str, seed: int, policy: str, out: Path, binary: Path,
                   px4: bool):
    """`sim run` with a real autopilot (ArduPilot's firmware, or PX4 with ``px4``): the run, or the exit code when
    it failed (2: the PX4 given exits before it ever connects, so it is no usable PX4; 1: it failed later, or never
    connected within its boot budget; 130: interrupted). The autopilot is stopped in every case (the run's
    ``finally``)."""
    from sim.firmware.process import FirmwareError, stop_on_terminate
    from sim.px4.lockstep import PX4Unusable
    from sim.px4.process import PX4Error
    from sim.runner import Run

    who, option = ("PX4", "px4") if px4 else ("the firmware", "firmware")
    print(f"returnlink: {'PX4' if px4 else 'firmware'} {binary}", file=sys.stderr)
    try:
        with stop_on_terminate():
            return Run(sc, kind, seed, progress=not args.quiet, policy=policy, log_path=out / f"{option}.log",
                       **{option: binary}).run()
    except PX4Unusable as e:
        raise px4_unusable(binary, e) from None
    except (FirmwareError, PX4Error) as e:
        print(f"returnlink: {who} failed: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"returnlink: interrupted; {who} was stopped", file=sys.stderr)
        return 130
