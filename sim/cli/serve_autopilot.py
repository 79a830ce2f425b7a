"""``returnlink sim serve --vehicle ardurover|px4rover``: the real autopilot behind the radio proxy, flying its own
failsafe, with returnlink's Lua applet aboard (ArduPilot), or with --policy companion returnlink companion between
the two: the plant ``sim run`` flies, served by the one real-time loop (``sim.serve.Server``)."""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

from sim.cli.common import (
    DEFAULT_PEERS,
    Refusal,
    fail,
    firmware_binary,
    parm_file,
    policy_for,
    px4_dir,
    px4_unusable,
    serve_state,
    serving_line,
    warn_heartbeat_speedup,
    writable_dir,
)


@dataclass(frozen=True)
class Autopilot:
    """What serving one real autopilot takes: its binary, log, failure, the plant options that give it, and how it
    is named."""

    who: str  # as the messages name it
    binary: Path
    log: str  # the file in the output directory its output goes to
    failure: type[Exception]  # what its process raises when it fails
    unusable: tuple[type[Exception], ...]  # a failure that says the binary given is no usable one (exit 2)
    link: str  # where the companion sits
    boots: str  # what it needs before it is ready
    options: dict = field(default_factory=dict)  # the plant's options: the binary, and the pace for one that keeps it


def _ardupilot(args: argparse.Namespace) -> Autopilot:
    from sim.firmware.process import FirmwareError

    binary = firmware_binary(args.firmware)
    return Autopilot("the ArduPilot firmware", binary, "firmware.log", FirmwareError, (),
                     "the firmware's telemetry port", "its EKF needs a GPS fix first",
                     {"firmware": binary, "speedup": args.speedup})


def _px4(args: argparse.Namespace) -> Autopilot:
    from sim.px4.lockstep import PX4Unusable
    from sim.px4.process import PX4Error

    binary = px4_dir(args.px4)
    return Autopilot("PX4", binary, "px4.log", PX4Error, (PX4Unusable,), "its telemetry link",
                     "EKF2 needs its sensors and a GPS fix first", {"px4": binary})


def command(args: argparse.Namespace, sc, kind: str) -> int:
    """Serve the autopilot of vehicle ``kind`` until it stops, the run's duration ends or the user interrupts;
    then its trajectory. 1: the autopilot failed; 2: the one given is no usable PX4."""
    from sim.firmware.process import stop_on_terminate
    from sim.registry import BY_POLICY, Outside, needing, outside
    from sim.report import trajectory

    policy = policy_for(args, kind)
    companion = BY_POLICY[policy].beside
    px4 = outside(kind) is Outside.PX4
    if px4 and args.firmware:
        raise fail(f"--firmware goes with --vehicle {' or '.join(needing(Outside.ARDUPILOT))}; PX4 is found by "
                   "--px4 DIR or RETURNLINK_PX4")
    who = outside(kind).label
    if not companion:
        _refuse_companion_options(args, who)
    pilot = (_px4 if px4 else _ardupilot)(args)
    out = Path(args.out) if args.out else Path("out") / f"serve-{sc.name}-{kind}"
    writable_dir(out)
    peers = tuple(args.peer) if args.peer else DEFAULT_PEERS
    server, keystore = _server(args, sc, kind, policy, companion, pilot, peers, out)
    _announce(args, sc, policy, companion, pilot, peers, server, keystore)
    try:
        with stop_on_terminate():
            server.serve(args.speedup, args.duration)
    except pilot.failure as e:
        if isinstance(e, pilot.unusable):
            raise px4_unusable(pilot.binary, e) from None
        print(f"returnlink: {pilot.who} failed: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"returnlink: stopped; {pilot.who} was stopped", file=sys.stderr)
    finally:
        server.close()
    if server.ticks:
        print(f"returnlink: wrote {trajectory(server, out / 'trajectory.png')}", file=sys.stderr)
    return 0


def _refuse_companion_options(args: argparse.Namespace, who: str) -> None:
    """--params, --key and --state configure returnlink; an autopilot flying without it keeps its own (exit 2)."""
    for flag in ("params", "key", "state"):
        if getattr(args, flag):
            raise fail(f"--{flag} configures returnlink's own vehicle (or, with --policy companion, the "
                       f"companion); {who} keeps its parameters and signing in itself (set them over MAVLink)")


def _server(args: argparse.Namespace, sc, kind: str, policy: str, companion: bool, pilot: Autopilot, peers,
            out: Path):
    """The server and the companion's keystore (None without one), bound; a damaged kept file: exit 2; a port in
    use: a Refusal (exit 2)."""
    from link.storage import StoredFileError
    from sim.serve import Server

    try:
        kept = {}
        keystore = None
        if companion:
            params = parm_file(args.params)
            keystore, epochs = serve_state(args)
            kept = {"param_file": params, "keystore": keystore, "epochs_file": epochs}
        server = Server(sc, kind, args.seed, args.port, peers, args.perfect_link, policy=policy,
                        log_path=out / pilot.log, **kept, **pilot.options)
        if companion:
            warn_heartbeat_speedup(args.speedup, server.plant.companion.params["LNK_TIMEOUT"], "companion")
        return server, keystore
    except StoredFileError as e:  # a damaged kept file: refuse to start rather than boot on defaults
        raise fail(str(e)) from None
    except OSError as e:
        raise Refusal(f"cannot bind 127.0.0.1:{args.port}: {e}") from None


def _announce(args: argparse.Namespace, sc, policy: str, companion: bool, pilot: Autopilot, peers, server,
              keystore) -> None:
    """The opening line on stderr: the scenario, the autopilot and what flies its returns, where it listens and
    sends, and the companion's signing key."""
    from sim.registry import BY_POLICY

    host, port = server.address
    what = (f"returnlink companion on {pilot.link}" if companion else "returnlink's Lua applet aboard"
            if BY_POLICY[policy].aboard else f"policy {policy}")
    print(f"returnlink: {sc.name} with {pilot.who} ({pilot.binary}, {what}) on udp {host}:{port}, sending to "
          + serving_line(peers, args.perfect_link)
          + ("" if keystore is None else f"; the companion signs with key {keystore.key.fingerprint} from "
             f"{keystore.path}"), file=sys.stderr, flush=True)
    print(f"returnlink: {pilot.who} is booting ({pilot.boots})...", file=sys.stderr, flush=True)
