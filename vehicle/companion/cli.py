"""``returnlink companion``: the companion on a real computer, between an autopilot's telemetry port and a radio.

The imperative shell around ``vehicle.companion.app.Companion``: it opens the two connections, checks that an
ArduPilot Rover answers on the autopilot's, runs the 50 Hz loop on the wall clock and serves both links between
ticks. ``--check`` and ``--configure`` talk to the autopilot about its parameters and leave.

Anything wrong at start (a connection string, a file, an autopilot that cannot be reached or is not a Rover) is
reported by name with exit code 2 before the loop starts. Once running, nothing on either link ends the process:
a lost autopilot is reported and retried.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import sys
import time
from pathlib import Path

from link import args as types
from vehicle.app import DT
from vehicle.companion.app import Companion
from vehicle.companion.links import ConnError, parse_conn
from vehicle.companion.setup import check, differing, report

START_WAIT = 15.0  # s to reach the autopilot and hear its heartbeat
PARAM_WAIT = 3.0  # s to wait for the autopilot's parameters
PARAM_RETRY = 1.0


def add_parser(sub) -> None:
    c = sub.add_parser("companion", help="run returnlink beside an ArduPilot Rover, between its telemetry port "
                                         "and the ground-station radio (docs/architecture.md §11)")
    c.add_argument("--autopilot", required=True, metavar="CONN",
                   help="the autopilot: serial:/dev/ttyAMA0:921600, tcp:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT")
    c.add_argument("--gcs", metavar="CONN", help="the ground side (the radio or a ground station), same forms")
    c.add_argument("--params", help="the companion's returnlink parameters (.parm) to boot from and save to")
    c.add_argument("--key", help="signing key file (returnlink keys new): sign the ground side, obey only signed "
                                 "frames; its timestamp is kept in FILE.stamp")
    c.add_argument("--wait", type=types.SECONDS, default=START_WAIT,
                   help=f"seconds to reach the autopilot at start (default {START_WAIT:g})")
    mode = c.add_mutually_exclusive_group()
    mode.add_argument("--check", action="store_true",
                      help="print the autopilot parameters companion mode needs and which differ, then exit "
                           "(1 if any differ)")
    mode.add_argument("--configure", action="store_true", help="set the autopilot parameters that differ, "
                                                                 "printing each change, then exit")
    c.set_defaults(func=run)


def fail(message: str) -> int:
    print(f"returnlink: error: {message}", file=sys.stderr)
    return 2


class CompanionLoop:
    """The two links and the companion, served on the wall clock."""

    def __init__(self, autopilot, companion_factory) -> None:
        self.ap = autopilot
        self.gcs = None
        self.t0 = time.monotonic()
        self.companion: Companion = companion_factory(self.ap.write, self._to_ground)
        self.next_tick = self.t0

    def _to_ground(self, data: bytes) -> None:
        if self.gcs is not None:
            self.gcs.write(data)

    def now(self) -> float:
        return time.monotonic() - self.t0

    def step(self) -> None:
        """Wait for input until the next tick is due, take it, and tick when due."""
        links = [x for x in (self.ap, self.gcs) if x is not None]
        fds = [fd for fd in (x.fileno() for x in links) if fd is not None]
        timeout = max(0.0, self.next_tick - time.monotonic())
        try:
            select.select(fds, [], [], timeout)
        except (OSError, ValueError):  # a link closed under us: it reconnects on poll
            time.sleep(timeout)
        c = self.companion
        for data, _ in self.ap.read():
            c.from_autopilot(data, self.now())
        if self.gcs is not None:
            for data, source in self.gcs.read():
                c.from_ground(data, self.now(), source)
        now = time.monotonic()
        if now >= self.next_tick:
            c.tick(now - self.t0)
            self.next_tick += DT
            if now - self.next_tick > 1.0:  # stalled (suspended, starved): carry on from now, no burst of ticks
                self.next_tick = now + DT
        for x in links:
            x.poll()

    def run_for(self, seconds: float, done=lambda: False) -> bool:
        """Serve until ``done()`` or ``seconds`` pass; whether ``done()`` came true."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if done():
                return True
            self.step()
        return done()

    def read_params(self, names: list[str], wait: float = PARAM_WAIT) -> dict[str, float]:
        """The autopilot's values of ``names`` (absent ones left out: another firmware version)."""
        d = self.companion.driver
        end = time.monotonic() + wait
        while time.monotonic() < end:
            missing = [n for n in names if n not in d.seen.params]
            if not missing:
                break
            for name in missing:
                d.send_message(d.enc.param_request_read_encode(d.seen.sysid, d.seen.compid, name.encode(), -1))
            self.run_for(min(PARAM_RETRY, end - time.monotonic()),
                         lambda: all(n in d.seen.params for n in names))
        return {n: d.seen.params[n] for n in names if n in d.seen.params}

    def set_param(self, name: str, value: float) -> bool:
        d = self.companion.driver
        ptype = d.seen.param_types.get(name, 9)  # (MAV_PARAM_TYPE_REAL32 if never seen)
        for _ in range(3):
            d.seen.params.pop(name, None)
            d.send_message(d.enc.param_set_encode(d.seen.sysid, d.seen.compid, name.encode(), value, ptype))
            if self.run_for(PARAM_RETRY * 2, lambda: name in d.seen.params):
                return d.seen.params[name] == value
        return False


def _connect(conn, wait: float):
    """Open the autopilot's link, retrying a refused TCP connection until ``wait`` s pass (SITL or a booting
    autopilot may not listen yet). ConnError naming the connection when it cannot be opened."""
    from vehicle.companion.links import open_link

    end = time.monotonic() + wait
    while True:
        try:
            return open_link(conn, timeout=min(5.0, max(0.5, wait)))
        except OSError as e:
            if time.monotonic() >= end:
                raise ConnError(f"cannot reach the autopilot at {conn.text}: {e.strerror or e}") from None
            time.sleep(0.5)


def _epochs_path(params: str | None) -> Path:
    if params:
        return Path(params).with_suffix(".epochs")
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "returnlink" / "companion.epochs"


def run(args: argparse.Namespace) -> int:
    from link.signing import stamp_from_unix
    from link.storage import StoredFileError, remove_leftovers
    from vehicle.epochs import EpochLog
    from vehicle.keystore import KeyStore
    from vehicle.params import load_defaults

    try:
        ap_conn = parse_conn(args.autopilot)
        gcs_conn = parse_conn(args.gcs) if args.gcs else None
    except ConnError as e:
        return fail(str(e))
    config_only = args.check or args.configure
    if gcs_conn is None and not config_only:
        return fail("--gcs CONN is needed (the ground side), unless --check or --configure")
    param_file = Path(args.params) if args.params else None
    try:
        if param_file is not None:
            remove_leftovers(param_file)
        params = load_defaults(param_file) if param_file is not None and param_file.is_file() else load_defaults()
        keystore = KeyStore.open(args.key) if args.key else None
        epochs = EpochLog(None if config_only else _epochs_path(args.params))
    except StoredFileError as e:
        return fail(str(e))
    except OSError as e:
        return fail(f"cannot prepare the companion's files: {e}")
    try:
        ap = _connect(ap_conn, args.wait)
    except ConnError as e:
        return fail(str(e))

    def build(to_autopilot, to_ground) -> Companion:
        return Companion(params, to_autopilot, to_ground, keystore=keystore,
                         stamp=lambda t: stamp_from_unix(time.time()), boot_epoch=epochs.boot,
                         param_file=param_file, on_epoch=epochs.issued, autopilot_name=ap_conn.text)

    shell = CompanionLoop(ap, build)
    c = shell.companion
    heard = shell.run_for(args.wait, lambda: c.driver.seen.sysid is not None and c.driver.seen.mode is not None)
    if not heard:
        ap.close()
        return fail(f"no autopilot heartbeat on {ap_conn.text} within {args.wait:g} s")
    if c.identity_problem:
        ap.close()
        return fail(f"{ap_conn.text}: {c.identity_problem}; companion mode drives ArduPilot Rover only")
    if config_only:
        code = _configure(shell, args.configure)
        ap.close()
        return code
    try:
        from vehicle.companion.links import open_link

        shell.gcs = open_link(gcs_conn, pinned=c.pinned)
    except (ConnError, OSError) as e:
        ap.close()
        return fail(str(e) if isinstance(e, ConnError) else f"cannot reach {gcs_conn.text}: {e}")
    _announce(shell, ap_conn.text, gcs_conn.text, keystore)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    try:
        while not stop:
            shell.step()
    except KeyboardInterrupt:
        pass
    finally:
        c.close()
        ap.close()
        shell.gcs.close()
    return 0


def _announce(shell: CompanionLoop, ap_text: str, gcs_text: str, keystore) -> None:
    """The banner, and a warning (stderr and STATUSTEXT) if the backstop is not set up."""
    c = shell.companion
    d = c.driver.seen
    rows = check(shell.read_params([r.need.name for r in check({})] + ["MAV_GCS_SYSID", "SYSID_MYGCS"]))
    gcs_sysid = int(d.params.get("MAV_GCS_SYSID", d.params.get("SYSID_MYGCS", 255)))
    print(f"returnlink companion: ArduPilot Rover (system {d.sysid}) on {ap_text}, ground side on {gcs_text}; "
          f"component 191, keepalive as system {gcs_sysid}"
          + ("" if keystore is None else f"; signing with key {keystore.key.fingerprint}"), file=sys.stderr,
          flush=True)
    bad = differing(rows)
    if bad:
        names = ", ".join(f"{r.need.name}={r.value:g}" for r in bad)
        print(f"returnlink: warning: the backstop is not set up ({names}): a dead companion would not end in the "
              f"autopilot's failsafe. Run with --check to see, --configure to set them.", file=sys.stderr,
              flush=True)
        c.notice(0, "backstop", f"companion backstop not set up: {names}", c.t)


def _configure(shell: CompanionLoop, configure: bool) -> int:
    names = [r.need.name for r in check({})]
    rows = check(shell.read_params(names))
    if not configure:
        print(report(rows))
        return 1 if differing(rows) else 0
    failed = False
    for r in differing(rows):
        assert r.value is not None
        new = r.need.fix(r.value)
        if shell.set_param(r.need.name, new):
            print(f"set {r.need.name} {r.value:g} -> {new:g} ({r.need.why})")
        else:
            failed = True
            print(f"returnlink: error: the autopilot did not take {r.need.name} = {new:g}", file=sys.stderr)
    rows = check(shell.read_params(names))
    if not failed and not differing(rows):
        print("the autopilot is set up for companion mode")
    print(report(rows))
    return 1 if failed or differing(rows) else 0
