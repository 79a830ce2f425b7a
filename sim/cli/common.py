"""What the sub-commands of ``returnlink`` share: how a bad argument found after parsing is told (exit 2), the
scenario and the autopilot a command is given, and the options several sub-commands take.

Imports of the simulator stay inside the functions, so a ``returnlink gcs`` command does not load it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from link import args as types

# where a served vehicle sends before anyone talks to it: QGroundControl's and MAVSDK's ports
DEFAULT_PEERS = (("127.0.0.1", 14550), ("127.0.0.1", 14540))


def fail(message: str) -> SystemExit:
    """A bad argument or file found after parsing: the message on stderr, exit 2."""
    print(f"returnlink: error: {message}", file=sys.stderr)
    return SystemExit(2)


def usage_error(message: str) -> int:
    """The same message as ``fail``, as the command's return code (2) rather than raised."""
    print(f"returnlink: error: {message}", file=sys.stderr)
    return 2


class Refusal(Exception):
    """A bad argument or file found deep in a command: ``sim.cli.main`` catches it and returns ``usage_error``'s
    2, so a step can say no without every caller passing a return code up."""


def scenario(name: str, seed: int | None = None, args: argparse.Namespace | None = None):
    """The scenario (a generated one drawn from ``seed``, saying how many draws were redrawn); exit 2 if bad."""
    return scenario_world(name, seed, args=args)[0]


def scenario_world(name: str, seed: int | None, announce: bool = True, args: argparse.Namespace | None = None):
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


def writable_dir(out: Path) -> None:
    """Create ``out`` and write a file into it now, so a bad --out fails before minutes of simulation."""
    probe = out / ".returnlink-write-test"
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise fail(f"cannot write to output directory {out}: {e.strerror or e}") from None


def parm_file(path: str | None) -> Path | None:
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
            raise fail(str(e)) from None
    return p


def policy_for(args: argparse.Namespace, kind: str) -> str:
    """--policy, or the default for the vehicle; a policy the vehicle cannot fly exits 2 saying why (both from the
    plant registry, ``sim.registry``)."""
    from sim import registry

    policy = args.policy or registry.default_policy(kind)
    if not registry.flies(policy, kind):
        raise fail(registry.why_not(policy, kind))
    return policy


def px4_dir(option: str | None) -> Path:
    """The PX4 directory (--px4, RETURNLINK_PX4); none, or one that is not a PX4 rover build: exit 2 saying so."""
    from sim.px4.locate import PX4NotFound, find_px4

    try:
        return find_px4(option)
    except PX4NotFound as e:
        raise fail(str(e)) from None


def firmware_binary(option: str | None) -> Path:
    """The firmware binary (--firmware, RETURNLINK_ARDUROVER, or ardurover on PATH); none: exit 2 saying so."""
    from sim.firmware.locate import FirmwareNotFound, find_firmware

    try:
        return find_firmware(option)
    except FirmwareNotFound as e:
        raise fail(str(e)) from None


def autopilot_path(args: argparse.Namespace, vehicle: str) -> Path | None:
    """Where this machine keeps the outside program ``vehicle`` needs (the plant registry says which: the ArduPilot
    firmware from --firmware, PX4 from --px4, or their defaults), None for a vehicle with returnlink aboard; not
    found: exit 2 saying so."""
    from sim.registry import Outside, outside

    program = outside(vehicle)
    if program is Outside.ARDUPILOT:
        return firmware_binary(args.firmware)
    if program is Outside.PX4:
        return px4_dir(args.px4)
    return None


def px4_unusable(px4: Path, e: Exception) -> SystemExit:
    """Exit 2 for a PX4 that exits before it ever connects: no usable PX4, and how to give one."""
    from sim.px4.locate import ENV

    return fail(f"{px4} is not a PX4 that runs here ({e}); give a working one with --px4 DIR or {ENV}=DIR (a ready "
                "one: ../shared/px4/, see its README.md)")


def print_wrote(paths) -> None:
    """The closing line of a command that wrote files: each path, comma separated."""
    print("  wrote " + ", ".join(str(p) for p in paths))


def add_px4_option(parser) -> None:
    parser.add_argument("--px4", metavar="DIR",
                        help="PX4 rover SITL for vehicle px4rover: a directory holding bin/px4 and etc/ (default: "
                             "$RETURNLINK_PX4)")


def add_firmware_option(parser) -> None:
    parser.add_argument("--firmware", metavar="PATH",
                        help="ArduPilot Rover SITL binary for vehicle ardurover (default: $RETURNLINK_ARDUROVER, "
                             "else ardurover on PATH)")


def add_map_options(p) -> None:
    """``--station`` and ``--radio``, for a ``map:PATH.yaml`` world (docs/architecture.md §7.2)."""
    p.add_argument("--station", type=types.STATION, metavar="X,Y",
                   help="with map:PATH.yaml: where the ground station stands (map frame, metres: x east, y north)")
    p.add_argument("--radio", metavar="FILE",
                   help="a [radio] table (returnlink site fit writes one) on top of the scenario's radio")


def epochs_file(args: argparse.Namespace) -> Path:
    """Where `sim serve` keeps the epochs it issued: ``--state DIR``, else beside ``--params FILE``, else the
    user's state directory ($XDG_STATE_HOME/returnlink, by default ~/.local/state/returnlink)."""
    import os

    if args.state:
        return Path(args.state) / "returnlink.epochs"
    if args.params:
        return Path(args.params).with_suffix(".epochs")
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "returnlink" / "returnlink.epochs"


def serve_state(args: argparse.Namespace):
    """`sim serve`'s signing key (--key) and where the epochs it issues are kept (--state): (keystore or None,
    path), the state directory created; a bad key file or an uncreatable directory: a Refusal saying so (exit 2)."""
    from link.storage import StoredFileError

    keystore = None
    if args.key:
        from vehicle.keystore import KeyStore

        try:
            keystore = KeyStore.open(args.key)
        except StoredFileError as e:
            raise Refusal(f"key file {e}") from None
    epochs = epochs_file(args)
    try:
        epochs.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise Refusal(f"cannot create the state directory {epochs.parent}: {e.strerror or e}") from None
    return keystore, epochs


def warn_heartbeat_speedup(speedup: float, timeout: float, who: str) -> None:
    """Ground stations heartbeat once a wall-clock second: at --speedup K that is once every K simulated s."""
    if speedup > 1 and speedup >= timeout / 1.5:
        print(f"returnlink: warning: ground stations send a heartbeat once a wall-clock second, which at --speedup "
              f"{speedup:g} is once every {speedup:g} simulated s; with LNK_TIMEOUT {timeout:g} s the {who} will "
              f"think an idle station lost. Raise LNK_TIMEOUT or lower --speedup.", file=sys.stderr)


def serving_line(peers, perfect_link: bool) -> str:
    """The end of `sim serve`'s opening line: where it sends before anyone talks, and whether through the radio."""
    return (", ".join(f"{h}:{p}" for h, p in peers) + ("" if perfect_link else ", through the radio model"))
