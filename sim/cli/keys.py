"""``returnlink keys new``: a MAVLink signing key file (mode 0600), random or from a passphrase."""

from __future__ import annotations

import argparse
import sys


def add_parser(sub) -> None:
    keys = sub.add_parser("keys", help="MAVLink signing keys").add_subparsers(dest="keys_command", required=True)
    new = keys.add_parser("new", help="write a fresh random signing key (mode 0600)")
    new.add_argument("file")
    new.add_argument("--force", action="store_true", help="replace an existing key file")
    new.add_argument("--passphrase", help="derive the key from a passphrase instead (SHA-256, as MAVProxy's "
                     "'signing key PASSPHRASE' does), so MAVProxy can sign with it")
    new.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
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
