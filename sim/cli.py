"""The ``returnlink`` command line: one entry point for the simulator, the ground station and set-up helpers.

Bad arguments exit with code 2 and a message naming the problem (argparse's convention).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from link import args as types


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


def _scenario(name: str, seed: int | None = None, args: argparse.Namespace | None = None):
    """The scenario (a generated one drawn from ``seed``, saying how many draws were redrawn); exit 2 if bad."""
    return _scenario_world(name, seed, args=args)[0]


def _scenario_world(name: str, seed: int | None, announce: bool = True, args: argparse.Namespace | None = None):
    """The scenario with the map options of ``args`` (``--station``, ``--radio``) where it has them."""
    from sim.scenario import ScenarioError, read_radio_file
    from sim.worlds.resolve import load

    station = getattr(args, "station", None)
    radio_file = getattr(args, "radio", None)
    try:
        radio = read_radio_file(radio_file) if radio_file else None
        sc, redraws = load(name, seed, station, radio)
    except (ScenarioError, OSError, UnicodeDecodeError) as e:
        print(f"returnlink: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    if redraws is not None and announce:
        print(f"returnlink: generated {sc.name} from seed {sc.seed} ({redraws} draw{'' if redraws == 1 else 's'} "
              "redrawn)", file=sys.stderr)
    return sc, redraws


def _fail(message: str) -> SystemExit:
    """A bad argument or file found after parsing: the message on stderr, exit 2."""
    print(f"returnlink: error: {message}", file=sys.stderr)
    return SystemExit(2)


def _writable_dir(out: Path) -> None:
    """Create ``out`` and write a file into it now, so a bad --out fails before minutes of simulation."""
    probe = out / ".returnlink-write-test"
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise _fail(f"cannot write to output directory {out}: {e.strerror or e}") from None


def _parm_file(path: str | None) -> Path | None:
    """A .parm file to boot from is checked before anything runs, as strictly as the vehicle reads it at boot
    (an empty or cut-short file too): errors by file and line, exit 2."""
    from link.storage import StoredFileError
    from vehicle.params import read_parm_file

    if path is None:
        return None
    p = Path(path)
    if p.exists():
        try:
            read_parm_file(p)
        except StoredFileError as e:
            raise _fail(str(e)) from None
    return p


def _policy_for(args: argparse.Namespace, kind: str) -> str:
    """--policy, or the default for the vehicle; a policy the vehicle cannot fly exits 2."""
    from sim.policies import (
        DEFAULT_FIRMWARE_POLICY,
        DEFAULT_POLICY,
        DEFAULT_PX4_POLICY,
        FIRMWARE_VEHICLE,
        PX4_FAILSAFE_POLICIES,
        PX4_VEHICLE,
        flies,
        vehicle_for,
    )

    default = {FIRMWARE_VEHICLE: DEFAULT_FIRMWARE_POLICY, PX4_VEHICLE: DEFAULT_PX4_POLICY}.get(kind, DEFAULT_POLICY)
    policy = args.policy or default
    if not flies(policy, kind):
        if kind == FIRMWARE_VEHICLE:
            raise _fail(f"vehicle {kind} flies the ArduPilot firmware's own failsafes, returnlink beside it or the "
                        "Lua applet in it: --policy ardupilot-hold, ardupilot-rtl, ardupilot-smartrtl, companion or "
                        f"applet (got {policy})")
        if kind == PX4_VEHICLE:
            raise _fail(f"vehicle {kind} flies PX4's own data-link failsafe or returnlink beside it: --policy "
                        f"{' or '.join(PX4_FAILSAFE_POLICIES)} or companion (got {policy})")
        if policy == "companion":
            raise _fail(f"policy {policy} runs beside a real autopilot: use --vehicle {FIRMWARE_VEHICLE} or "
                        f"{PX4_VEHICLE}")
        need = "the ArduPilot firmware" if vehicle_for(policy) == FIRMWARE_VEHICLE else "PX4"
        raise _fail(f"policy {policy} needs {need}: use --vehicle {vehicle_for(policy)}")
    return policy


def _px4(option: str | None) -> Path:
    """The PX4 directory (--px4, RETURNLINK_PX4); none, or one that is not a PX4 rover build: exit 2 saying so."""
    from sim.px4.locate import PX4NotFound, find_px4

    try:
        return find_px4(option)
    except PX4NotFound as e:
        raise _fail(str(e)) from None


def _firmware(option: str | None) -> Path:
    """The firmware binary (--firmware, RETURNLINK_ARDUROVER, or ardurover on PATH); none: exit 2 saying so."""
    from sim.firmware.locate import FirmwareNotFound, find_firmware

    try:
        return find_firmware(option)
    except FirmwareNotFound as e:
        raise _fail(str(e)) from None


def _cmd_sim_run(args: argparse.Namespace) -> int:
    from sim import outputs
    from sim.policies import FIRMWARE_VEHICLE, PX4_VEHICLE

    if args.replay:
        return _cmd_sim_replay(args)
    if args.scenario is None:
        return _usage_error("sim run needs a SCENARIO (or --replay DIR TRIAL)")
    sc = _run_overrides(_scenario(args.scenario, args.seed, args), args)
    kind = args.vehicle or sc.vehicle
    policy = _policy_for(args, kind)
    if args.px4 and kind != PX4_VEHICLE:
        raise _fail(f"--px4 goes with --vehicle {PX4_VEHICLE} (got vehicle {kind})")
    firmware = _firmware(args.firmware) if kind == FIRMWARE_VEHICLE else None
    px4 = _px4(args.px4) if kind == PX4_VEHICLE else None
    seed = sc.seed if args.seed is None else args.seed
    out = Path(args.out) if args.out else Path("out") / f"{sc.name.replace(':', '-')}-{kind}-{seed}"
    _writable_dir(out)
    print(f"returnlink: running {sc.name} with the {kind} (seed {seed}, policy {policy}), "
          f"{sc.duration:g} simulated s", file=sys.stderr)
    from sim.runner import Run

    if px4 is None and firmware is None:
        run = Run(sc, kind, seed, progress=not args.quiet, policy=policy).run()
    else:
        run = _run_autopilot(args, sc, kind, seed, policy, out, px4 or firmware, px4 is not None)
        if isinstance(run, int):
            return run
    m = run.metrics = outputs.compute(run)
    try:
        paths = outputs.write(run, out, plots=not args.no_plots)
    except OSError as e:  # the directory was writable a moment ago: a full disk, a removed directory
        print(outputs.summary(run, m))
        raise _fail(f"cannot write the results to {out}: {e}") from None
    print(outputs.summary(run, m))
    print("  wrote " + ", ".join(str(p) for p in paths))
    return 0 if m["passed"] else 1


def _px4_unusable(px4: Path, e: Exception) -> SystemExit:
    """Exit 2 for a PX4 that exits before it ever connects: no usable PX4, and how to give one."""
    from sim.px4.locate import ENV

    return _fail(f"{px4} is not a PX4 that runs here ({e}); give a working one with --px4 DIR or {ENV}=DIR (a ready "
                 "one: ../shared/px4/, see its README.md)")


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
        raise _px4_unusable(binary, e) from None
    except (FirmwareError, PX4Error) as e:
        print(f"returnlink: {who} failed: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"returnlink: interrupted; {who} was stopped", file=sys.stderr)
        return 130


def _epochs_file(args: argparse.Namespace):
    """Where `sim serve` keeps the epochs it issued: ``--state DIR``, else beside ``--params FILE``, else the
    user's state directory ($XDG_STATE_HOME/returnlink, by default ~/.local/state/returnlink)."""
    import os
    from pathlib import Path

    if args.state:
        return Path(args.state) / "returnlink.epochs"
    if args.params:
        return Path(args.params).with_suffix(".epochs")
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "returnlink" / "returnlink.epochs"


def _usage_error(message: str) -> int:
    print(f"returnlink: error: {message}", file=sys.stderr)
    return 2


def _param_assignment(text: str) -> tuple[str, float]:
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


def _plan_spec(text: str) -> tuple:
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


def _cmd_sim_replay(args: argparse.Namespace) -> int:
    """Run a stored campaign trial again from its parquet row's inputs; its metrics must come out the same."""
    import json
    from dataclasses import replace
    from pathlib import Path

    from link.storage import StoredFileError
    from sim import outputs
    from sim.campaign.store import JSON_METRICS, TRIALS_FILE, read_rows
    from sim.campaign.trial import same_metrics, simulate, trial_from_row
    from sim.policies import AUTOPILOT_VEHICLES, FIRMWARE_VEHICLE, PX4_VEHICLE

    if args.scenario or args.param or args.plan is not None or args.seed is not None or args.vehicle:
        return _usage_error("--replay takes every input from the stored trial; give no SCENARIO, --seed, "
                            "--vehicle, --param or --plan with it")
    directory, wanted = args.replay
    path = Path(directory) / TRIALS_FILE
    if not path.is_file():
        return _usage_error(f"{path}: no such campaign file (run `returnlink sim sweep SPEC --out {directory}`)")
    try:
        rows = read_rows(path)
    except StoredFileError as e:
        return _usage_error(str(e))
    found = [r for r in rows if r["trial_id"].startswith(wanted)] if wanted else []
    if len(found) != 1:
        return _usage_error(f"{path}: {'no' if not found else 'more than one'} trial {wanted!r}")
    row = found[0]
    trial = trial_from_row(row)
    if trial.vehicle == FIRMWARE_VEHICLE:
        trial = replace(trial, firmware=str(_firmware(args.firmware)))
    elif trial.vehicle == PX4_VEHICLE:
        trial = replace(trial, firmware=str(_px4(args.px4)))
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
    print("  wrote " + ", ".join(str(p) for p in paths))
    if row["status"] == "error":
        print(f"returnlink: the stored row is an error ({row.get('error')}); nothing to compare", file=sys.stderr)
        return 0 if m["passed"] else 1
    stored = {k: (json.loads(v) if isinstance(v, str) and k in JSON_METRICS else v)
              for k, v in row.items() if k in m}
    fresh = json.loads(json.dumps({k: m[k] for k in stored}))
    if trial.vehicle in AUTOPILOT_VEHICLES:
        from sim.firmware.metrics import differing

        differ = [k for k in differing(stored, fresh) if k not in ("scenario", "vehicle", "seed", "policy")]
        same = "metrics match the stored trial within the firmware's repeatability (sim.firmware.metrics.TOLERANCE)"
    else:
        differ = [k for k in same_metrics(stored, fresh) if k not in ("scenario", "vehicle", "seed", "policy")]
        same = "metrics identical to the stored trial (real_time_factor aside)"
    if differ and trial.vehicle in AUTOPILOT_VEHICLES:
        print(f"returnlink: the firmware did not repeat the stored trial exactly: {', '.join(differ)} differ beyond "
              "its repeatability (see sim/firmware/metrics.py: ArduPilot SITL's own threads make a firmware run "
              "repeatable only within a tick or so, and the radio can turn that tick into another outcome)",
              file=sys.stderr)
        return 0 if m["passed"] else 1
    if differ:
        print(f"returnlink: error: replay differs from the stored trial in {', '.join(differ)}", file=sys.stderr)
        return 1
    print(f"  {same}")
    return 0 if m["passed"] else 1


def _cmd_sim_sweep(args: argparse.Namespace) -> int:
    from pathlib import Path

    from sim.campaign.spec import SpecError, load_spec

    if args.workers is not None and args.workers < 1:
        return _usage_error(f"--workers must be at least 1, got {args.workers}")
    if args.address and args.address != "auto":
        host, _, port = args.address.rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            return _usage_error(f"--address must be auto or HOST:PORT, got {args.address!r}")
    try:
        spec = load_spec(args.spec)
    except SpecError as e:
        return _usage_error(str(e))
    if any(t.vehicle == "ardurover" for t in spec.trials):
        import os
        from dataclasses import replace

        from sim.firmware.locate import ENV

        firmware = str(_firmware(args.firmware))
        os.environ[ENV] = firmware  # for workers that run a stored trial again (a resumed or retried one)
        spec = replace(spec, trials=tuple(replace(t, firmware=firmware) if t.vehicle == "ardurover" else t
                                          for t in spec.trials))
    if any(t.vehicle == "px4rover" for t in spec.trials):
        import os
        from dataclasses import replace

        from sim.px4.locate import ENV as PX4_ENV

        px4 = str(_px4(args.px4))
        os.environ[PX4_ENV] = px4  # for workers that run a stored trial again (a resumed or retried one)
        spec = replace(spec, trials=tuple(replace(t, firmware=px4) if t.vehicle == "px4rover" else t
                                          for t in spec.trials))
    out = Path(args.out) if args.out else Path("out") / f"sweep-{Path(args.spec).stem}"
    from link.storage import StoredFileError
    from sim.campaign import sweep
    from sim.campaign.executors import RayExecutor, SerialExecutor

    try:
        store = sweep.Store(out)
    except StoredFileError as e:
        return _usage_error(str(e))
    try:
        # a campaign already complete in DIR only rewrites its summary and report: no Ray to start
        executor = RayExecutor(args.workers, args.address) if store.pending(spec.trials) else SerialExecutor()
        with executor:
            done = sweep.run_sweep(spec, store, executor, progress=not args.quiet)
    except ConnectionError as e:
        return _usage_error(f"cannot join Ray at {args.address}: {e}")
    except KeyboardInterrupt:
        print(f"returnlink: interrupted; finished trials are kept in {out} (run again to resume)", file=sys.stderr)
        return 130
    sweep.print_summary(done)
    return 0


def _add_sweep_parser(sim) -> None:
    sw = sim.add_parser("sweep", help="a campaign: a grid of trials on Ray, with a summary and a report")
    sw.add_argument("spec", help="campaign spec (.toml): scenarios, vehicles, seeds, params, policies, timeout_s")
    sw.add_argument("--out", help="campaign directory (default: out/sweep-SPEC); running again resumes it")
    sw.add_argument("--workers", type=int, help="trials at a time (default: every CPU of this machine or cluster)")
    sw.add_argument("--address", help="join a Ray cluster: auto or HOST:PORT (default: a local Ray, started here)")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_firmware_option(sw)
    _add_px4_option(sw)
    sw.set_defaults(func=_cmd_sim_sweep)


def _add_px4_option(parser) -> None:
    parser.add_argument("--px4", metavar="DIR",
                        help="PX4 rover SITL for vehicle px4rover: a directory holding bin/px4 and etc/ (default: "
                             "$RETURNLINK_PX4)")


def _add_firmware_option(parser) -> None:
    parser.add_argument("--firmware", metavar="PATH",
                        help="ArduPilot Rover SITL binary for vehicle ardurover (default: $RETURNLINK_ARDUROVER, "
                             "else ardurover on PATH)")


def _add_run_campaign_options(run) -> None:
    run.add_argument("--replay", nargs=2, metavar=("DIR", "TRIAL"),
                     help="run a campaign's trial again from DIR/trials.parquet (a unique id prefix will do)")
    run.add_argument("--param", type=_param_assignment, action="append", metavar="NAME=VALUE",
                     help="set a vehicle parameter on top of the scenario's (repeatable)")
    run.add_argument("--plan", type=_plan_spec, metavar="SPEC",
                     help="return plan instead of the scenario's, e.g. 'rtl:50 | loiter:30 | launch'")
    run.add_argument("--no-plots", action="store_true", help="skip trajectory.png and timeline.png")


def _cmd_sim_serve_autopilot(args: argparse.Namespace, sc, kind: str) -> int:
    """`sim serve --vehicle ardurover|px4rover`: the real autopilot behind the radio proxy, flying its own failsafe,
    or with --policy companion returnlink companion between the two (the ArduPilot firmware paces itself; PX4 is
    paced to the wall clock by its server)."""
    from link.storage import StoredFileError
    from sim.firmware.process import stop_on_terminate
    from sim.firmware.report import trajectory
    from sim.policies import APPLET_POLICY, COMPANION_POLICY, PX4_VEHICLE

    policy = _policy_for(args, kind)
    companion = policy == COMPANION_POLICY
    px4 = kind == PX4_VEHICLE
    if px4 and args.firmware:
        raise _fail("--firmware goes with --vehicle ardurover; PX4 is found by --px4 DIR or RETURNLINK_PX4")
    who = "PX4" if px4 else "the ArduPilot firmware"
    if not companion:
        for flag in ("params", "key", "state"):
            if getattr(args, flag):
                raise _fail(f"--{flag} configures returnlink's own vehicle (or, with --policy companion, the "
                            f"companion); {who} keeps its parameters and signing in itself (set them over MAVLink)")
    unusable: tuple[type, ...] = ()  # a failure that says the binary given is no usable one (exit 2)
    if px4:
        from sim.px4.lockstep import PX4Unusable
        from sim.px4.process import PX4Error as failure
        from sim.px4.serve import PX4CompanionServer as companion_server
        from sim.px4.serve import PX4Server as server_type

        binary, log, unusable = _px4(args.px4), "px4.log", (PX4Unusable,)
    else:
        from sim.firmware.companion_serve import CompanionServer as companion_server
        from sim.firmware.process import FirmwareError as failure
        from sim.firmware.serve import AppletServer, FirmwareServer

        server_type = AppletServer if policy == APPLET_POLICY else FirmwareServer

        binary, log = _firmware(args.firmware), "firmware.log"
    out = Path(args.out) if args.out else Path("out") / f"serve-{sc.name}-{kind}"
    _writable_dir(out)
    peers = tuple(args.peer) if args.peer else (("127.0.0.1", 14550), ("127.0.0.1", 14540))
    try:
        if companion:
            params = _parm_file(args.params)
            state = _serve_state(args)
            if state is None:
                return 2
            keystore, epochs = state
            server = companion_server(sc, args.seed, binary, args.port, peers, args.perfect_link, args.speedup,
                                      args.duration, log_path=out / log, param_file=params, keystore=keystore,
                                      epochs_file=epochs)
            _warn_heartbeat_speedup(args.speedup, server.companion.params["LNK_TIMEOUT"], "companion")
        else:
            keystore = None
            server = server_type(sc, args.seed, policy, binary, args.port, peers, args.perfect_link, args.speedup,
                                 args.duration, log_path=out / log)
    except StoredFileError as e:  # a damaged kept file: refuse to start rather than boot on defaults
        raise _fail(str(e)) from None
    except OSError as e:
        print(f"returnlink: error: cannot bind 127.0.0.1:{args.port}: {e}", file=sys.stderr)
        return 2
    host, port = server.address
    where = "its telemetry link" if px4 else "the firmware's telemetry port"
    what = (f"returnlink companion on {where}" if companion else "returnlink's Lua applet aboard"
            if policy == APPLET_POLICY else f"policy {policy}")
    print(f"returnlink: {sc.name} with {who} ({binary}, {what}) on udp {host}:{port}, sending to "
          + ", ".join(f"{h}:{p}" for h, p in peers) + ("" if args.perfect_link else ", through the radio model")
          + ("" if keystore is None else f"; the companion signs with key {keystore.key.fingerprint} from "
             f"{keystore.path}"), file=sys.stderr, flush=True)
    try:
        with stop_on_terminate():
            server.run()
    except failure as e:
        if isinstance(e, unusable):
            raise _px4_unusable(binary, e) from None
        print(f"returnlink: {who} failed: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"returnlink: stopped; {who} was stopped", file=sys.stderr)
    if server.rows:
        print(f"returnlink: wrote {trajectory(server, out / 'trajectory.png')}", file=sys.stderr)
    return 0


def _serve_state(args: argparse.Namespace):
    """`sim serve`'s signing key (--key) and where the epochs it issues are kept (--state): (keystore or None,
    path), the state directory created; a bad key file or an uncreatable directory: the message, and None (exit 2)."""
    from link.storage import StoredFileError

    keystore = None
    if args.key:
        from vehicle.keystore import KeyStore

        try:
            keystore = KeyStore.open(args.key)
        except StoredFileError as e:
            print(f"returnlink: error: key file {e}", file=sys.stderr)
            return None
    epochs = _epochs_file(args)
    try:
        epochs.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        print(f"returnlink: error: cannot create the state directory {epochs.parent}: {e.strerror or e}",
              file=sys.stderr)
        return None
    return keystore, epochs


def _warn_heartbeat_speedup(speedup: float, timeout: float, who: str) -> None:
    """Ground stations heartbeat once a wall-clock second: at --speedup K that is once every K simulated s."""
    if speedup > 1 and speedup >= timeout / 1.5:
        print(f"returnlink: warning: ground stations send a heartbeat once a wall-clock second, which at --speedup "
              f"{speedup:g} is once every {speedup:g} simulated s; with LNK_TIMEOUT {timeout:g} s the {who} will "
              f"think an idle station lost. Raise LNK_TIMEOUT or lower --speedup.", file=sys.stderr)


def _cmd_sim_serve(args: argparse.Namespace) -> int:
    from link.storage import StoredFileError
    from sim.policies import FIRMWARE_VEHICLE
    from sim.serve import Server

    sc = _scenario(args.scenario, args.seed, args)
    if args.px4 and args.vehicle != "px4rover":
        raise _fail(f"--px4 goes with --vehicle px4rover (got vehicle {args.vehicle or sc.vehicle})")
    if args.vehicle in (FIRMWARE_VEHICLE, "px4rover"):
        return _cmd_sim_serve_autopilot(args, sc, args.vehicle)
    if args.policy or args.firmware:
        raise _fail("--policy and --firmware go with --vehicle ardurover or px4rover (the native vehicle flies its "
                    "own plan)")
    params = _parm_file(args.params)
    if args.out:
        _writable_dir(Path(args.out))  # the plot is written on exit: know now that it can be
    peers = tuple(args.peer) if args.peer else (("127.0.0.1", 14550), ("127.0.0.1", 14540))
    state = _serve_state(args)
    if state is None:
        return 2
    keystore, epochs = state
    try:
        server = Server(sc, args.vehicle, args.seed, args.port, peers, args.perfect_link, params, keystore, epochs)
    except StoredFileError as e:  # a damaged kept file: refuse to start rather than boot on defaults
        print(f"returnlink: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"returnlink: error: cannot bind 127.0.0.1:{args.port}: {e}", file=sys.stderr)
        return 2
    _warn_heartbeat_speedup(args.speedup, server.vehicle.params["LNK_TIMEOUT"], "vehicle")
    host, port = server.address
    print(f"returnlink: {sc.name} ({server.kind}) on udp {host}:{port}, sending to "
          + ", ".join(f"{h}:{p}" for h, p in peers) + ("" if args.perfect_link else ", through the radio model")
          + ("" if keystore is None else f"; signing with key {keystore.key.fingerprint} from {keystore.path}"),
          file=sys.stderr, flush=True)
    try:
        server.serve(args.speedup, args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
        out = Path(args.out) if args.out else Path("out") / f"serve-{sc.name}-{server.kind}"
        try:
            print(f"returnlink: wrote {server.plot(out / 'trajectory.png')}", file=sys.stderr)
        except OSError as e:
            raise _fail(f"cannot write the plot to {out}: {e}") from None
    return 0


def _cmd_sim_world(args: argparse.Namespace) -> int:
    """`sim world`: a scenario's map (world.png) and the world as an ordinary scenario file (world.toml)."""
    from link.storage import write_atomic
    from sim.worlds.check import check
    from sim.worlds.render import render
    from sim.worlds.toml_out import to_toml

    sc, redraws = _scenario_world(args.scenario, args.seed, announce=False, args=args)
    out = Path(args.out)
    _writable_dir(out)
    verdict = check(sc)
    if sc.site is not None:  # a map world's walls are its cells: the route's clearance comes from the map
        from dataclasses import replace

        from sim.maps.routes import route_clearance

        verdict = replace(verdict, clearance_m=route_clearance(sc))
    try:
        write_atomic(out / "world.toml", to_toml(sc).encode("utf-8"))
        png = render(sc, out / "world.png", verdict)
    except OSError as e:
        raise _fail(f"cannot write the world to {out}: {e}") from None
    drawn = "not generated" if redraws is None else f"{redraws} draw{'' if redraws == 1 else 's'} redrawn"
    print(f"returnlink: {sc.name}, seed {sc.seed}: {drawn}")
    print(f"  {sc.description}")
    print(f"  route {verdict.clearance_m:.2f} m from the nearest wall; link {verdict.start_margin_db:.1f} dB over "
          f"the threshold at the start, " + ("dies at " + ", ".join(f"{c:.1f}" for c in verdict.dead_at)
                                             if verdict.dead_at else "never dies") + " (north, east; mean radio)")
    for problem in verdict.problems:  # a generated world never has one; a hand-drawn one may
        print(f"  fails the generated worlds' validity check: {problem}")
    print(f"  wrote {png}, {out / 'world.toml'}")
    return 0


def _add_world_parser(sim) -> None:
    w = sim.add_parser("world", help="draw a scenario's map and write it out as a scenario file (gen:KIND too)")
    w.add_argument("scenario", help="a built-in scenario, gen:office, gen:mine, gen:culvert, map:PATH.yaml (with "
                                    "--station), or a .toml file")
    w.add_argument("--seed", type=types.SEED, help="the seed that picks a generated world (default: the scenario's)")
    w.add_argument("--out", required=True, help="directory for world.png and world.toml")
    add_map_options(w)
    w.set_defaults(func=_cmd_sim_world)


def add_map_options(p) -> None:
    """``--station`` and ``--radio``, for a ``map:PATH.yaml`` world (docs/architecture.md §7.2)."""
    p.add_argument("--station", type=types.STATION, metavar="X,Y",
                   help="with map:PATH.yaml: where the ground station stands (map frame, metres: x east, y north)")
    p.add_argument("--radio", metavar="FILE",
                   help="a [radio] table (returnlink site fit writes one) on top of the scenario's radio")


def _site_world(args: argparse.Namespace):
    """The map, site, station and radio of a `site` command's YAML, --station and --radio; exit 2 naming the
    file and field when any is bad."""
    from sim.maps import mapfile
    from sim.maps.grid import Site
    from sim.scenario import STATION_POWER_DBM, ScenarioError, read_radio_file
    from sim.world import Station

    try:
        occupancy = mapfile.read(args.map)
        model, loss = read_radio_file(args.radio) if args.radio else ({}, {})
    except (mapfile.MapError, ScenarioError) as e:
        raise _fail(str(e)) from None
    from dataclasses import replace

    from link.radio import RadioParams

    site = replace(Site(str(Path(args.map).resolve()), digest=occupancy.digest), **loss)
    x, y = args.station
    power = getattr(args, "power_dbm", 20.0)
    if not STATION_POWER_DBM[0] <= power <= STATION_POWER_DBM[1]:
        raise _fail(f"--power-dbm must be within {STATION_POWER_DBM[0]:g}..{STATION_POWER_DBM[1]:g}, got {power:g}")
    station = Station("gcs", y, x, 255, power)
    grid = site.grid()
    problem = grid.station_problem(station.x, station.y)
    if problem:
        raise _fail(f"{args.map}: station: the station at x {x:g}, y {y:g} (map frame) {problem}")
    return site, grid, station, replace(RadioParams(), **model), {**model, **loss}


def _cmd_site_survey(args: argparse.Namespace) -> int:
    """`site survey`: the predicted coverage, and with --trials a campaign of returns beyond it."""
    from link.storage import write_atomic
    from sim.maps import survey

    if args.trials is not None and not 1 <= args.trials <= 1000:
        return _usage_error(f"--trials must be within 1..1000, got {args.trials}")
    policies = [p.strip() for p in args.policies.split(",") if p.strip()]
    vehicles = [v.strip() for v in args.vehicles.split(",") if v.strip()]
    out = Path(args.out)
    _writable_dir(out)
    site, grid, station, radio, radio_table = _site_world(args)
    print(f"returnlink: surveying {args.map} ({grid.cols} x {grid.rows} cells at {grid.res:g} m) from the station "
          f"at x {args.station[0]:g}, y {args.station[1]:g}", file=sys.stderr)
    s = survey.survey(grid, site, station, radio)
    try:
        paths = [survey.write_csv(s, out / "coverage.csv"),
                 survey.draw(s, grid, station, out / "coverage.png",
                             f"{Path(args.map).name}: predicted coverage from the station (walls {site.wall_db:g} dB "
                             f"a crossing + {site.wall_db_per_m:g} dB/m, exponent {radio.exponent:g})")]
    except OSError as e:
        raise _fail(f"cannot write the survey to {out}: {e}") from None
    print(f"returnlink: {args.map}")
    for line in survey.summary_lines(s):
        print(line)
    print("  wrote " + ", ".join(str(p) for p in paths))
    if args.trials is None:
        return 0
    name = f"site:{Path(args.map).stem}"
    write_atomic(out / "site.toml", survey.site_scenario(Path(args.map), args.station, radio_table, name).encode())
    write_atomic(out / "campaign.toml", survey.campaign_spec(args.trials, policies, vehicles).encode())
    sweep_args = argparse.Namespace(spec=str(out / "campaign.toml"), out=str(out), workers=args.workers,
                                    address=None, quiet=args.quiet, firmware=args.firmware, px4=None)
    return _cmd_sim_sweep(sweep_args)


def _add_site_parser(sub) -> None:
    site = sub.add_parser("site", help="your own site: a ROS map_server map as the world (docs/site.md)")
    cmds = site.add_subparsers(dest="site_command", required=True)
    sv = cmds.add_parser("survey", help="predicted coverage over the map, and a campaign of returns beyond it")
    sv.add_argument("map", help="the map_server YAML (image, resolution, origin, ...)")
    sv.add_argument("--station", type=types.STATION, required=True, metavar="X,Y",
                    help="where the ground station stands (map frame, metres: x east, y north)")
    sv.add_argument("--out", required=True, help="directory for coverage.csv, coverage.png and the campaign")
    sv.add_argument("--radio", metavar="FILE", help="a [radio] table (returnlink site fit writes one)")
    sv.add_argument("--power-dbm", type=float, default=20.0, help="the station's transmit power (default 20 dBm)")
    sv.add_argument("--trials", type=int, help="also fly a campaign: returns to this many goals beyond coverage "
                                               "(each seed draws one), every policy and robot")
    sv.add_argument("--policies", default="returnlink,backup,smartrtl",
                    help="the campaign's policies (default returnlink,backup,smartrtl)")
    sv.add_argument("--vehicles", default="rover,legged", help="the campaign's robots (default rover,legged)")
    sv.add_argument("--workers", type=int, help="trials at a time (default: every CPU)")
    sv.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_firmware_option(sv)
    sv.set_defaults(func=_cmd_site_survey)
    fit = cmds.add_parser("fit", help="fit the radio model to a real drive's .tlog")
    fit.add_argument("map", help="the map_server YAML the drive was made in")
    fit.add_argument("--station", type=types.STATION, required=True, metavar="X,Y",
                     help="where the ground station stood (map frame, metres: x east, y north)")
    fit.add_argument("--tlog", required=True, help="the drive's MAVLink log (.tlog)")
    fit.add_argument("--out", required=True, help="directory for radio.toml and the fit's plot")
    fit.add_argument("--anchor", type=types.point("anchor"), metavar="LAT,LON",
                     help="the map origin's latitude and longitude, to place GLOBAL_POSITION_INT on the map")
    fit.add_argument("--power-dbm", type=float, default=20.0, help="the station's transmit power (default 20 dBm)")
    fit.set_defaults(func=_cmd_site_fit)


def _cmd_site_fit(args: argparse.Namespace) -> int:
    """`site fit`: the radio model's parameters from a logged drive, with their uncertainty."""
    from sim.maps import fit

    out = Path(args.out)
    _writable_dir(out)
    site, grid, station, radio, _ = _site_world(argparse.Namespace(**{**vars(args), "radio": None}))
    try:
        samples = fit.samples_from_tlog(Path(args.tlog), grid, site, station, args.anchor)
        result = fit.fit(samples, radio, station.power_dbm)
    except fit.FitError as e:
        raise _fail(str(e)) from None
    try:
        paths = fit.write(result, samples, out)
    except OSError as e:
        raise _fail(f"cannot write the fit to {out}: {e}") from None
    for line in fit.report_lines(result, samples):
        print(line)
    print("  wrote " + ", ".join(str(p) for p in paths))
    return 0


def _cmd_keys(args: argparse.Namespace) -> int:
    from link.signing import Key
    from vehicle.keystore import write_key

    if args.passphrase is not None and not args.passphrase:
        print("returnlink: error: --passphrase must not be empty", file=sys.stderr)
        return 2
    key = Key.generate() if args.passphrase is None else Key.from_passphrase(args.passphrase)
    try:
        write_key(args.file, key, force=args.force)
    except FileExistsError as e:
        print(f"returnlink: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"returnlink: error: cannot write {args.file}: {e.strerror or e}", file=sys.stderr)
        return 2
    print(f"returnlink: wrote signing key {key.fingerprint} to {args.file} (mode 0600)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from sim.policies import (
        APPLET_POLICY,
        COMPANION_POLICY,
        DEFAULT_POLICY,
        FAILSAFE_POLICIES,
        POLICY_NAMES,
        PX4_FAILSAFE_POLICIES,
    )

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
    run.add_argument("scenario", nargs="?", help="a built-in scenario name, gen:KIND (a world generated from the "
                                                "seed: gen:office, gen:mine, gen:culvert), map:PATH.yaml (a world "
                                                "made from a ROS map_server map, with --station) or a .toml file")
    run.add_argument("--seed", type=types.SEED, help="random seed (default: the scenario's)")
    run.add_argument("--vehicle", choices=["rover", "legged", "ardurover", "px4rover"],
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
    _add_firmware_option(run)
    _add_px4_option(run)
    add_map_options(run)
    _add_run_campaign_options(run)
    run.set_defaults(func=_cmd_sim_run)
    _add_sweep_parser(sim)
    _add_world_parser(sim)
    _add_site_parser(sub)
    serve = sim.add_parser("serve", help="run a scenario in real time over UDP for MAVSDK, MAVProxy, QGC")
    serve.add_argument("scenario", help="a built-in scenario name, gen:KIND (drawn from --seed) or a .toml file")
    serve.add_argument("--vehicle", choices=["rover", "legged", "ardurover", "px4rover"],
                       help="robot model (default: the scenario's); ardurover: the real ArduPilot firmware; "
                            "px4rover: the real PX4 rover")
    serve.add_argument("--policy", choices=(*FAILSAFE_POLICIES, COMPANION_POLICY, APPLET_POLICY,
                                            *PX4_FAILSAFE_POLICIES),
                       help="with --vehicle ardurover: its GCS failsafe (default ardupilot-smartrtl), companion: "
                            "returnlink companion on its telemetry port (--params, --key, --state configure it), or "
                            "applet: returnlink's Lua applet aboard the firmware (its RLNK_ parameters over MAVLink); "
                            "with --vehicle px4rover: px4-hold or px4-return (default), PX4's data-link failsafe, or "
                            "companion")
    _add_firmware_option(serve)
    _add_px4_option(serve)
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
    serve.set_defaults(func=_cmd_sim_serve)
    keys = sub.add_parser("keys", help="MAVLink signing keys").add_subparsers(dest="keys_command", required=True)
    new = keys.add_parser("new", help="write a fresh random signing key (mode 0600)")
    new.add_argument("file")
    new.add_argument("--force", action="store_true", help="replace an existing key file")
    new.add_argument("--passphrase", help="derive the key from a passphrase instead (SHA-256, as MAVProxy's "
                     "'signing key PASSPHRASE' does), so MAVProxy can sign with it")
    new.set_defaults(func=_cmd_keys)
    from gcs import cli as gcs_cli

    gcs_cli.add_parser(sub)
    from vehicle.companion import cli as companion_cli

    companion_cli.add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
