"""``returnlink gcs ...``: the ground station from a shell. Every failure prints what went wrong and exits 1
(2 for bad arguments or files)."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from gcs.plans import PlanError, describe, parse_spec, read_wpl, write_wpl
from link import args as types


def add_parser(sub) -> None:
    g = sub.add_parser("gcs", help="talk to a returnlink vehicle as a ground station")
    g.add_argument("--url", type=types.url, default="udpin:127.0.0.1:14550",
                   help="udpin:HOST:PORT or udpout:HOST:PORT")
    g.add_argument("--sysid", type=types.SYSID, default=255, help="this ground station's MAVLink system id")
    g.add_argument("--compid", type=types.COMPID, default=190, help="this ground station's component id")
    g.add_argument("--target", type=types.SYSID, default=1, help="the vehicle's system id")
    g.add_argument("--timeout", type=types.SECONDS, default=10.0, help="seconds to wait for the vehicle")
    g.add_argument("--key", help="signing key file (64 hex characters): sign everything, believe only the "
                   "vehicle's signed frames")
    gs = g.add_subparsers(dest="gcs_command", required=True)
    gs.add_parser("status", help="one status report")
    w = gs.add_parser("watch", help="live one-screen view (Ctrl-C to stop)")
    w.add_argument("--seconds", type=types.SECONDS_OR_INF, default=math.inf)
    a = gs.add_parser("acquire", help="take operator control (the root lease)")
    a.add_argument("--allow-takeover", action="store_true", help="let another station take over")
    gs.add_parser("release", help="give operator control up")
    c = gs.add_parser("claim", help="claim an execution lease (default: the current unclaimed one)")
    c.add_argument("index", type=types.integer(-1, 65534, "lease index"), nargs="?", default=-1)
    gs.add_parser("expire", help="expire the current lease (the return plan runs)")
    gs.add_parser("rtl", help="return now (RTL)")
    gs.add_parser("hold", help="take the vehicle back and hold still")
    arm = gs.add_parser("arm", help="arm (or --disarm)")
    arm.add_argument("--disarm", action="store_true")
    d = gs.add_parser("drive", help="drive with a NED velocity for a while")
    d.add_argument("north", type=types.VELOCITY)
    d.add_argument("east", type=types.VELOCITY)
    d.add_argument("seconds", type=types.number("seconds", 0.0, 3600.0, lo_open=True))
    plan = gs.add_parser("plan", help="the return plan").add_subparsers(dest="plan_command", required=True)
    up = plan.add_parser("upload", help="upload a QGC WPL 110 file or --spec 'rtl:50 | loiter:30 | launch'")
    up.add_argument("file", nargs="?")
    up.add_argument("--spec")
    down = plan.add_parser("download", help="download the plan (to FILE, or print it)")
    down.add_argument("file", nargs="?")
    show = plan.add_parser("show", help="show a plan file or spec without a vehicle")
    show.add_argument("file", nargs="?")
    show.add_argument("--spec")
    plan.add_parser("clear", help="clear the plan (the default plan applies)")
    param = gs.add_parser("param", help="parameters").add_subparsers(dest="param_command", required=True)
    pg = param.add_parser("get", help="one parameter, or all")
    pg.add_argument("name", nargs="?")
    ps = param.add_parser("set")
    ps.add_argument("name")
    ps.add_argument("value", type=types.number("value"))
    pl = param.add_parser("load", help="set every parameter of a .parm file")
    pl.add_argument("file")
    pv = param.add_parser("save", help="save every parameter to a .parm file")
    pv.add_argument("file")
    g.set_defaults(func=run)


def _plan_items(args):
    try:
        if args.spec:
            return parse_spec(args.spec)
        if not args.file:
            raise PlanError("give a plan file or --spec")
        path = Path(args.file)
        return read_wpl(path.read_text(encoding="utf-8"), str(path))
    except (PlanError, OSError, UnicodeDecodeError) as e:
        print(f"returnlink gcs: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None


def _parm_file(args) -> None:
    """A .parm file to load is read and checked before connecting: an error names file and line, exit 2."""
    from vehicle.params import ParamError, parse_parm

    try:
        parse_parm(Path(args.file).read_text(encoding="utf-8"), args.file)
    except (ParamError, OSError, UnicodeDecodeError) as e:
        print(f"returnlink gcs: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None


def status_text(client) -> str:
    v = client.gs.vehicle
    st = v.status
    pos = "-" if v.position is None else f"N {v.position[0]:7.2f} m  E {v.position[1]:7.2f} m"
    lines = [f"vehicle {v.sysid}  armed {'yes' if v.armed else 'no'}  position {pos}"]
    if st is None:
        lines.append("no LEASE_STATUS yet")
    else:
        age = "never" if st.link_age is None else f"{st.link_age:.1f} s"
        lines.append(f"owner {st.owner or '-'}  epoch {st.epoch}  lease [{st.epoch},{st.current}]"
                     f"{'' if st.claimed else ' (unclaimed)'}  scheduled {st.scheduled}  state {st.state_name}")
        lines.append(f"last expiry {st.reason_name}  owner heard {age} ago  trail {st.trail_points} points")
        if st.return_start is not None:
            tgt = "-" if st.return_target is None else f"({st.return_target[0]:.1f}, {st.return_target[1]:.1f})"
            lines.append(f"return from ({st.return_start[0]:.1f}, {st.return_start[1]:.1f}) to {tgt}: "
                         f"displacement {st.displacement:.1f} / {st.max_displacement:.1f} m, "
                         f"{st.route_remaining:.1f} m to go")
    if v.radio_rssi is not None:
        lines.append(f"radio rssi {v.radio_rssi}")
    for e in client.gs.events[-5:]:
        lines.append(f"  event {e.t:7.1f}  {e.expired} -> {e.current}  {e.reason}  ({e.holder})")
    for t, text in client.gs.texts[-5:]:
        lines.append(f"  text  {t:7.1f}  {text}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from gcs.client import Client, GcsError

    if args.gcs_command == "plan" and args.plan_command == "show":
        print(describe(_plan_items(args)))
        return 0
    items = _plan_items(args) if args.gcs_command == "plan" and args.plan_command == "upload" else None
    key = None
    if args.key:
        from link.signing import KeyFileError, load_key

        try:
            key = load_key(args.key)
        except KeyFileError as e:
            print(f"returnlink gcs: error: key file {e}", file=sys.stderr)
            return 2
    if args.gcs_command == "param" and args.param_command == "load":
        _parm_file(args)
    try:
        with Client(args.url, args.sysid, args.compid, target=args.target, key=key) as c:
            c.connect(args.timeout)
            cmd = args.gcs_command
            if cmd == "status":
                c.pump(0.6)
                print(status_text(c))
            elif cmd == "watch":
                end = time.monotonic() + args.seconds
                try:
                    while time.monotonic() < end:
                        c.pump(0.5)
                        print("\033[2J\033[H" + status_text(c), flush=True)
                except KeyboardInterrupt:
                    pass
            elif cmd == "acquire":
                print(f"in control: epoch {c.acquire(args.allow_takeover)}")
            elif cmd == "release":
                c.release()
                print("released")
            elif cmd == "claim":
                print(f"claimed lease index {c.claim(args.index)}")
            elif cmd == "expire":
                c.pump(0.6)
                c.expire()
                print("current lease expired")
            elif cmd == "rtl":
                c.rtl()
                print("returning")
            elif cmd == "hold":
                c.hold()
                print("holding")
            elif cmd == "arm":
                c.arm(not args.disarm)
                print("disarmed" if args.disarm else "armed")
            elif cmd == "drive":
                c.drive_velocity(args.north, args.east, args.seconds)
                print(status_text(c))
            elif cmd == "plan":
                if args.plan_command == "upload":
                    c.upload(items)
                    print(f"uploaded {len(items)} items")
                elif args.plan_command == "download":
                    got = c.download()
                    if args.file:
                        Path(args.file).write_text(write_wpl(got), encoding="utf-8")
                        print(f"saved {len(got)} items to {args.file}")
                    else:
                        print(describe(got) if got else "no plan uploaded (the default plan applies)")
                else:
                    c.clear()
                    print("plan cleared")
            elif cmd == "param":
                pc = args.param_command
                if pc == "get" and args.name:
                    print(f"{args.name} {c.param_get(args.name):g}")
                elif pc == "get":
                    for k, v in c.param_all().items():
                        print(f"{k:<16} {v:g}")
                elif pc == "set":
                    print(f"{args.name} {c.param_set(args.name, args.value):g}")
                elif pc == "load":
                    print(f"set {c.param_load(Path(args.file))} parameters")
                else:
                    print(f"saved {c.param_save(Path(args.file))} parameters to {args.file}")
    except GcsError as e:
        print(f"returnlink gcs: {e}", file=sys.stderr)
        return 1
    except OSError as e:  # a file to save to that cannot be written
        print(f"returnlink gcs: error: {e}", file=sys.stderr)
        return 2
    return 0
