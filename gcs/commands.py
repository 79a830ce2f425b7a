"""The operator's commands as one table: each name with its arguments and what it does with a ``Client``.

``returnlink gcs COMMAND`` (``gcs/cli.py``, one short session per command) and ``returnlink gcs shell``
(``gcs/shell.py``, one long-lived station) both build their command lines from ``COMMANDS`` and run the chosen
entry with ``execute``, so the two speak exactly the same commands. A command raises ``GcsError`` when the vehicle
refused or did not answer (exit code 1) and ``UsageError`` for a command line that cannot be right (exit code 2);
``Command.check`` catches the second kind before any link is opened.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from gcs.client import Client, GcsError
from gcs.plans import PlanError, describe, parse_spec, read_wpl, write_wpl
from link import args as types
from link.storage import write_atomic


class UsageError(Exception):
    """A command line that does not parse: exit code 2 for a one-shot command, a message at the prompt."""


@dataclass
class Context:
    """What a command runs against: the client, where to print, and whether the link outlives the command."""

    client: Client
    out: TextIO
    session: bool = False  # True in the shell: a drive may run on after the command returns


@dataclass(frozen=True)
class Command:
    """One operator command: ``path`` ("plan upload"), help, how to add its arguments, what it does."""

    path: str
    help: str
    run: Callable[[Context, argparse.Namespace], None]
    arguments: Callable[[argparse.ArgumentParser], None] = lambda p: None
    vehicle: bool = True  # needs a connected vehicle
    where: str = "both"  # "both", "shell" (needs the long-lived link) or "oneshot"
    check: Callable[[argparse.Namespace, bool], None] = lambda a, session: None  # UsageError before any link


# ----- plans and reports (no socket) ----------------------------------------------------------------------------
def plan_items(a: argparse.Namespace) -> list:
    """The items of ``--spec`` or a plan FILE; UsageError names the problem (exit code 2)."""
    try:
        if a.spec:
            return parse_spec(a.spec)
        if not a.file:
            raise PlanError("give a plan file or --spec")
        path = Path(a.file)
        return read_wpl(path.read_text(encoding="utf-8"), str(path))
    except (PlanError, OSError, UnicodeDecodeError) as e:
        raise UsageError(str(e)) from None


def _check_parm(a: argparse.Namespace, session: bool) -> None:
    """A .parm file to load is read and checked before any link opens: an error names file and line (exit 2)."""
    from link.parameters import ParamError, parse_parm

    try:
        parse_parm(Path(a.file).read_text(encoding="utf-8"), a.file)
    except (ParamError, OSError, UnicodeDecodeError) as e:
        raise UsageError(str(e)) from None


def status_text(client: Client) -> str:
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


# ----- the commands ---------------------------------------------------------------------------------------------
def _say(ctx: Context, text: str) -> None:
    print(text, file=ctx.out, flush=True)


def _status(ctx, a):
    if not ctx.session:
        ctx.client.pump(0.6)
    _say(ctx, status_text(ctx.client))


def _watch(ctx, a):
    c = ctx.client
    end = c.now + a.seconds
    try:
        while c.now < end:
            c.pump(0.5)
            _say(ctx, ("\033[2J\033[H" if ctx.out.isatty() else "") + status_text(c))
    except KeyboardInterrupt:
        pass


def _acquire(ctx, a):
    _say(ctx, f"in control: epoch {ctx.client.acquire(a.allow_takeover)}")


def _release(ctx, a):
    ctx.client.release()
    _say(ctx, "released")


def _claim(ctx, a):
    _say(ctx, f"claimed lease index {ctx.client.claim(a.index)}")


def _expire(ctx, a):
    if not ctx.session:
        ctx.client.pump(0.6)
    ctx.client.expire()
    _say(ctx, "current lease expired")


def _rtl(ctx, a):
    ctx.client.rtl()
    _say(ctx, "returning")


def _hold(ctx, a):
    ctx.client.hold()
    _say(ctx, "holding")


def _arm(ctx, a):
    ctx.client.arm(not a.disarm)
    _say(ctx, "disarmed" if a.disarm else "armed")


_SECONDS = types.number("seconds", 0.0, 3600.0, lo_open=True)


def _drive_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("north", type=types.VELOCITY, help="m/s")
    p.add_argument("east", type=types.VELOCITY, help="m/s")
    p.add_argument("seconds", type=_SECONDS, nargs="?", help="how long (in the shell: until `stop` when left out)")


def _manual_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("forward", type=float, help="-1..1 of the vehicle's top speed (negative: backward)")
    p.add_argument("turn", type=float, help="-1..1 of the vehicle's top turn rate (positive: clockwise)")
    p.add_argument("seconds", type=_SECONDS, nargs="?", help="how long (in the shell: until `stop` when left out)")


def _check_duration(a: argparse.Namespace, session: bool) -> None:
    _duration(Context(None, sys.stdout, session), a)  # type: ignore[arg-type] - only the flag is read


def _check_plan(a: argparse.Namespace, session: bool) -> None:
    plan_items(a)


def _duration(ctx: Context, a: argparse.Namespace) -> float | None:
    s = a.seconds
    if s is None:
        if not ctx.session:
            raise UsageError("give SECONDS: a one-shot command ends its link when it returns (the shell can drive "
                             "until `stop`)")
        return None
    return s  # its argument type already refused anything but 0 < s <= 3600


def _drive(ctx, a):
    _stream(ctx, a, ("velocity", a.north, a.east))


def _manual(ctx, a):
    if not (-1 <= a.forward <= 1 and -1 <= a.turn <= 1):
        raise UsageError("forward and turn are fractions of the maximum: each between -1 and 1")
    _stream(ctx, a, ("manual", a.forward, a.turn))


def _stream(ctx: Context, a: argparse.Namespace, setpoint: tuple[str, float, float]) -> None:
    c = ctx.client
    seconds = _duration(ctx, a)
    kind, x, y = setpoint
    if seconds is not None:
        (c.drive_manual if kind == "manual" else c.drive_velocity)(x, y, seconds)
        _say(ctx, status_text(c) if not ctx.session else f"drove {seconds:g} s")
        return
    since = c.now
    if kind == "manual":
        c.gs.drive_manual(x, y)
    else:
        c.gs.drive_velocity(x, y)
    c.pump(0.5)
    try:
        c.check_teleop(since)
    except GcsError:
        c.gs.stop_streaming()
        raise
    _say(ctx, "driving (`stop` to stop)")


def _stop(ctx, a):
    ctx.client.stop_driving()
    _say(ctx, "stopped")


def _wait(ctx, a):
    if not (math.isfinite(a.seconds) and a.seconds >= 0):
        raise UsageError("seconds must be a non-negative number")
    ctx.client.pump(a.seconds)


def _plan_file_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", nargs="?")
    p.add_argument("--spec")


def _plan_upload(ctx, a):
    items = plan_items(a)
    ctx.client.upload(items)
    _say(ctx, f"uploaded {len(items)} items")


def _plan_download(ctx, a):
    got = ctx.client.download()
    if a.file:
        try:
            Path(a.file).write_text(write_wpl(got), encoding="utf-8")
        except OSError as e:
            raise UsageError(f"cannot write {a.file}: {e.strerror or e}") from None
        _say(ctx, f"saved {len(got)} items to {a.file}")
    else:
        _say(ctx, describe(got) if got else "no plan uploaded (the default plan applies)")


def _plan_show(ctx, a):
    _say(ctx, describe(plan_items(a)))


def _plan_clear(ctx, a):
    ctx.client.clear()
    _say(ctx, "plan cleared")


def _param_get(ctx, a):
    if a.name:
        _say(ctx, f"{a.name} {ctx.client.param_get(a.name):g}")
    else:
        for k, v in ctx.client.param_all().items():
            _say(ctx, f"{k:<16} {v:g}")


def _param_set(ctx, a):
    _say(ctx, f"{a.name} {ctx.client.param_set(a.name, a.value):g}")


def _param_load(ctx, a):
    _say(ctx, f"set {ctx.client.param_load(Path(a.file))} parameters")


def _param_save(ctx, a):
    try:
        n = ctx.client.param_save(Path(a.file))
    except OSError as e:
        raise UsageError(f"cannot write {a.file}: {e.strerror or e}") from None
    _say(ctx, f"saved {n} parameters to {a.file}")


def _file_get(ctx, a):
    data = ctx.client.fetch(a.name)
    if a.file:
        try:
            write_atomic(a.file, data)
        except OSError as e:
            raise UsageError(f"cannot write {a.file}: {e.strerror or e}") from None
        _say(ctx, f"saved {len(data)} bytes of {a.name} to {a.file}")
    else:
        ctx.out.write(data.decode("utf-8", "replace"))


def _args(*specs: tuple[tuple, dict]) -> Callable[[argparse.ArgumentParser], None]:
    def add(p: argparse.ArgumentParser) -> None:
        for names, kw in specs:
            p.add_argument(*names, **kw)
    return add


COMMANDS: tuple[Command, ...] = (
    Command("status", "one status report", _status),
    Command("watch", "live one-screen view (Ctrl-C to stop)", _watch,
            _args((("--seconds",), {"type": types.SECONDS_OR_INF, "default": math.inf}))),
    Command("acquire", "take operator control (the root lease)", _acquire,
            _args((("--allow-takeover",), {"action": "store_true", "help": "let another station take over"}))),
    Command("release", "give operator control up", _release),
    Command("claim", "claim an execution lease (default: the current unclaimed one)", _claim,
            _args((("index",), {"type": types.integer(-1, 65534, "lease index"), "nargs": "?", "default": -1}))),
    Command("expire", "expire the current lease (the return plan runs)", _expire),
    Command("rtl", "return now (RTL)", _rtl),
    Command("hold", "take the vehicle back and hold still", _hold),
    Command("arm", "arm (or --disarm)", _arm, _args((("--disarm",), {"action": "store_true"}))),
    Command("drive", "drive with a north/east velocity (m/s) for SECONDS (shell: until `stop`)", _drive, _drive_args,
            check=_check_duration),
    Command("manual", "drive MANUAL_CONTROL-style: FORWARD and TURN in -1..1 (shell: until `stop`)", _manual,
            _manual_args, check=_check_duration),
    Command("stop", "stop driving", _stop, where="shell"),
    Command("wait", "keep the link up for SECONDS (for scripts)", _wait,
            _args((("seconds",), {"type": float})), where="shell"),
    Command("plan upload", "upload a QGC WPL 110 file or --spec 'rtl:50 | loiter:30 | launch'", _plan_upload,
            _plan_file_args, check=_check_plan),
    Command("plan download", "download the plan (to FILE, or print it)", _plan_download,
            _args((("file",), {"nargs": "?"}))),
    Command("plan show", "show a plan file or spec without a vehicle", _plan_show, _plan_file_args, vehicle=False),
    Command("plan clear", "clear the plan (the default plan applies)", _plan_clear),
    Command("file get", "fetch a file the vehicle offers (linkmap.csv: its link map) to FILE, or print it",
            _file_get, _args((("name",), {}), (("file",), {"nargs": "?"}))),
    Command("param get", "one parameter, or all", _param_get, _args((("name",), {"nargs": "?"}))),
    Command("param set", "set a parameter", _param_set,
            _args((("name",), {}), (("value",), {"type": types.number("value")}))),
    Command("param load", "set every parameter of a .parm file", _param_load, _args((("file",), {})),
            check=_check_parm),
    Command("param save", "save every parameter to a .parm file", _param_save, _args((("file",), {}))),
)
GROUP_HELP = {"plan": "the return plan", "param": "parameters"}


def find(path: str) -> Command:
    for c in COMMANDS:
        if c.path == path:
            return c
    raise KeyError(path)


def add_commands(sub, where: str, parser_class: type[argparse.ArgumentParser] | None = None) -> None:
    """Add the table's commands for ``where`` ("oneshot" or "shell") to an argparse subparsers object. The chosen
    command's path lands in ``args.command_path``; one-shot groups keep their historic ``plan_command`` /
    ``param_command`` destinations."""
    groups: dict[str, object] = {}
    extra = {} if parser_class is None else {"parser_class": parser_class}
    for c in COMMANDS:
        if c.where not in ("both", where):
            continue
        head, _, tail = c.path.partition(" ")
        if tail:
            if head not in groups:
                g = sub.add_parser(head, help=GROUP_HELP.get(head))
                groups[head] = g.add_subparsers(dest=f"{head}_command", required=True, **extra)
            p = groups[head].add_parser(tail, help=c.help)
        else:
            p = sub.add_parser(c.path, help=c.help)
        c.arguments(p)
        p.set_defaults(command_path=c.path)


def execute(ctx: Context, a: argparse.Namespace) -> int:
    """Run one parsed command: 0 done, 1 refused or failed (message on stderr). UsageError propagates."""
    c = find(a.command_path)
    try:
        c.run(ctx, a)
    except GcsError as e:
        print(f"returnlink gcs: {e}", file=sys.stderr, flush=True)
        return 1
    return 0


