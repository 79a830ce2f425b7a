"""``returnlink companion``: the companion on a real computer, between an autopilot's telemetry port and a radio.

The imperative shell around ``vehicle.companion.app.Companion``: it opens the connections, checks that an
ArduPilot Rover or a PX4 rover answers on the autopilot's, runs the 50 Hz loop on the wall clock and serves every
link between ticks. ``--check`` and ``--configure`` talk to the autopilot about its parameters and leave.

``--gcs`` may be given several times (the telemetry radio and a network, docs/architecture.md §11.1): whatever goes
to the ground goes to every ground link, and what comes from any of them reaches the companion tagged with its link
and address (``GroundSource``), so the owner, a system id, is heard on whichever carries it. ``--log DIR`` records
every frame both ways in a telemetry log (``vehicle.companion.tlog``).

Anything wrong at start (a connection string, a file, a log directory, an autopilot that cannot be reached or is
not a Rover) is reported by name with exit code 2 before the loop starts. Once running, nothing on any link ends
the process: a lost autopilot is reported and retried, a ground link that fails to write is reported while the
others carry on, a log that cannot be written any more is reported and stops.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import struct
import sys
import time
from collections.abc import Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from link import args as types
from vehicle.companion.app import Companion
from vehicle.companion.links import Conn, ConnError, Framer, open_link, parse_conn, require_device
from vehicle.companion.setup import check, differing, needs_for, range_params, range_report, report
from vehicle.companion.tlog import FROM_AUTOPILOT, FROM_GROUND, TO_AUTOPILOT, TO_GROUND, Tlog, TlogError
from vehicle.port import DT

START_WAIT = 15.0  # s to reach the autopilot and hear its heartbeat
PARAM_WAIT = 3.0  # s to wait for the autopilot's parameters
PARAM_RETRY = 1.0
RANGE_WAIT = 2.0  # s for the range sensors' parameters (advice: an autopilot without them must not hold it up)
REPORT_EVERY = 10.0  # s between reports of the same ground link failing


def add_parser(sub) -> None:
    c = sub.add_parser("companion", help="run returnlink beside an ArduPilot Rover or a PX4 rover, between its "
                                         "telemetry port and the ground-station radio (docs/architecture.md §11)")
    c.add_argument("--autopilot", required=True, metavar="CONN",
                   help="the autopilot: serial:/dev/ttyAMA0:921600, tcp:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT")
    c.add_argument("--gcs", metavar="CONN", action="append",
                   help="a ground link (the radio or a ground station), same forms; give it again for more links "
                        "(e.g. the radio and the local network): the ground side is all of them")
    c.add_argument("--log", metavar="DIR", help="record every frame both ways in DIR/<UTC start time>.tlog "
                                                "(MAVProxy, mavlogdump and QGC read it)")
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


class GroundSource(NamedTuple):
    """Where a ground frame came from: which ``--gcs`` link (its index) and, on UDP, which address."""

    link: int
    addr: Hashable | None


@dataclass
class Ground:
    """One ground link, the framer that hands its bytes over in whole frames, and its failures reported so far."""

    index: int
    link: Any  # links.TcpLink | UdpLink | SerialLink, or a test's stand-in
    text: str
    framer: Framer = field(default_factory=Framer)
    reported: int = 0
    next_report: float = 0.0


class CompanionLoop:
    """The autopilot's link, the ground links and the companion, served on the wall clock; every frame through the
    log if there is one."""

    def __init__(self, autopilot, companion_factory, log: Tlog | None = None) -> None:
        self.ap = autopilot
        self.grounds: list[Ground] = []
        self.log = log
        self.log_reported = False
        self.t0 = time.monotonic()
        self.companion: Companion = companion_factory(self._to_autopilot, self._to_ground)
        self.next_tick = self.t0

    def add_ground(self, link, text: str, datagrams: bool = False) -> None:
        """Serve ``link`` as one more ground link (``datagrams``: UDP, each read whole in itself)."""
        self.grounds.append(Ground(len(self.grounds), link, text, Framer(stream=not datagrams)))

    def open_ground(self, conn: Conn) -> None:
        """Open ``conn`` as the next ground link; a UDP one keeps the addresses the companion pins on it."""
        i = len(self.grounds)

        def pinned() -> list[Hashable]:
            return [s.addr for s in self.companion.pinned()
                    if isinstance(s, GroundSource) and s.link == i and s.addr is not None]

        self.add_ground(open_link(conn, pinned=pinned), conn.text, datagrams=conn.kind in ("udpin", "udpout"))

    def _to_autopilot(self, data: bytes) -> None:
        if self.log is not None:
            self.log.write(TO_AUTOPILOT, data)
        self.ap.write(data)

    def _to_ground(self, data: bytes) -> None:
        """To every ground link; one that fails (unplugged, unreachable) is counted and reported, never fatal."""
        if self.log is not None:
            self.log.write(TO_GROUND, data)
        for g in self.grounds:
            try:
                g.link.write(data)
            except Exception as e:  # noqa: BLE001 - the links count their own OSErrors; anything else as well
                g.link.errors = getattr(g.link, "errors", 0) + 1
                g.link.last_error = f"{type(e).__name__}: {e}"

    def now(self) -> float:
        return time.monotonic() - self.t0

    def step(self) -> None:
        """Wait for input until the next tick is due, take it, and tick when due."""
        links = [self.ap, *(g.link for g in self.grounds)]
        fds = [fd for fd in (x.fileno() for x in links) if fd is not None]
        timeout = max(0.0, self.next_tick - time.monotonic())
        try:
            select.select(fds, [], [], timeout)
        except (OSError, ValueError):  # a link closed under us: it reconnects on poll
            time.sleep(timeout)
        c, log = self.companion, self.log
        for data, _ in self.ap.read():
            if log is not None:
                log.write(FROM_AUTOPILOT, data)
            c.from_autopilot(data, self.now())
        for g in self.grounds:
            for data, addr in g.link.read():
                pieces = g.framer.feed(data)  # whole frames only: the links share the companion's parser
                if not pieces:
                    continue
                whole = b"".join(pieces)
                if log is not None:
                    log.write(FROM_GROUND, whole)
                c.from_ground(whole, self.now(), GroundSource(g.index, addr))
        now = time.monotonic()
        if now >= self.next_tick:
            c.tick(now - self.t0)
            self.next_tick += DT
            if now - self.next_tick > 1.0:  # stalled (suspended, starved): carry on from now, no burst of ticks
                self.next_tick = now + DT
        for x in links:
            x.poll()
        if self.log is not None:
            self.log.flush_if_due()
        self._report(now)

    def _report(self, now: float) -> None:
        """Say (stderr and STATUSTEXT) that a ground link fails, at most every REPORT_EVERY s per link, and that
        the log stopped, once."""
        for g in self.grounds:
            errors = getattr(g.link, "errors", 0)
            if errors > g.reported and now >= g.next_report:
                g.reported, g.next_report = errors, now + REPORT_EVERY
                self._say(f"ground link {g.text}", f"ground link {g.text} failing ({errors} errors, last: "
                          f"{g.link.last_error}); the other links carry on")
        if self.log is not None and self.log.failed is not None and not self.log_reported:
            self.log_reported = True
            self._say("log", self.log.failed)

    def _say(self, topic: str, text: str) -> None:
        print(f"returnlink: warning: {text}", file=sys.stderr, flush=True)
        c = self.companion
        c.notice(0, topic, text, c.t)

    def close(self) -> None:
        """Every link, and the log (flushed)."""
        for x in [self.ap, *(g.link for g in self.grounds)]:
            x.close()
        if self.log is not None:
            self.log.close()

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
        """PARAM_SET in the parameter's own type and the autopilot's encoding (PX4: bytewise, and a PARAM_SET of
        another type is ignored), then whether the autopilot answered with ``value``."""
        d = self.companion.driver
        ptype = d.seen.param_types.get(name, 9)  # (MAV_PARAM_TYPE_REAL32 if never seen)
        wire = d.rules.param_wire(value, ptype)
        for _ in range(3):
            d.seen.params.pop(name, None)
            d.send_message(d.enc.param_set_encode(d.seen.sysid, d.seen.compid, name.encode(), wire, ptype))
            if self.run_for(PARAM_RETRY * 2, lambda: name in d.seen.params):
                return d.seen.params[name] == _float32(value)
        return False


def _float32(value: float) -> float:
    """``value`` as a REAL32 parameter holds it (what the autopilot answers)."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


def _connect(conn, wait: float):
    """Open the autopilot's link, retrying a refused TCP connection until ``wait`` s pass (SITL or a booting
    autopilot may not listen yet). ConnError naming the connection when it cannot be opened."""
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
        gcs_conns = [parse_conn(text) for text in args.gcs or []]
        for conn in gcs_conns:
            require_device(conn)
    except ConnError as e:
        return fail(str(e))
    config_only = args.check or args.configure
    if not gcs_conns and not config_only:
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
        log = Tlog.create(Path(args.log)) if args.log else None  # before anything connects: its frames are in it
    except TlogError as e:
        return fail(str(e))
    try:
        ap = _connect(ap_conn, args.wait)
    except ConnError as e:
        if log is not None:
            log.close()
        return fail(str(e))

    def build(to_autopilot, to_ground) -> Companion:
        return Companion(params, to_autopilot, to_ground, keystore=keystore,
                         stamp=lambda t: stamp_from_unix(time.time()), boot_epoch=epochs.boot,
                         param_file=param_file, on_epoch=epochs.issued, autopilot_name=ap_conn.text)

    shell = CompanionLoop(ap, build, log)
    try:
        return _serve(shell, args, ap_conn, gcs_conns, keystore)
    finally:
        shell.close()


def _serve(shell: CompanionLoop, args: argparse.Namespace, ap_conn: Conn, gcs_conns: list[Conn], keystore) -> int:
    """From the autopilot's link open to the end: its heartbeat, ``--check``/``--configure``, or the ground links
    and the loop until SIGTERM or ^C. The caller closes every link and the log."""
    c = shell.companion
    heard = shell.run_for(args.wait, lambda: c.driver.seen.sysid is not None and c.driver.seen.mode is not None)
    if not heard:
        return fail(f"no autopilot heartbeat on {ap_conn.text} within {args.wait:g} s")
    if c.identity_problem:
        return fail(f"{ap_conn.text}: {c.identity_problem}; companion mode drives ArduPilot Rover and PX4 rovers "
                    f"only")
    if args.check or args.configure:
        return _configure(shell, args.configure)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))  # (from here on a stop closes the log cleanly)
    for conn in gcs_conns:
        try:
            shell.open_ground(conn)
        except (ConnError, OSError) as e:
            return fail(str(e) if isinstance(e, ConnError) else f"cannot reach {conn.text}: {e}")
    _announce(shell, ap_conn.text, " and ".join(conn.text for conn in gcs_conns), keystore)
    try:
        while not stop:
            shell.step()
    except KeyboardInterrupt:
        pass
    finally:
        c.close()
    return 0


def _announce(shell: CompanionLoop, ap_text: str, gcs_text: str, keystore) -> None:
    """The banner, and a warning (stderr and STATUSTEXT) if the backstop is not set up."""
    c = shell.companion
    d = c.driver.seen
    needs = needs_for(d.autopilot)
    rows = check(shell.read_params([n.name for n in needs] + list(c.driver.rules.gcs_sysid_params)), needs)
    gcs_sysid = int(d.params.get("MAV_GCS_SYSID", d.params.get("SYSID_MYGCS", 255)))
    print(f"returnlink companion: {c.driver.rules.name} (system {d.sysid}) on {ap_text}, ground side on {gcs_text}; "
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
    needs = needs_for(shell.companion.driver.seen.autopilot)
    names = [n.name for n in needs]
    rows = check(shell.read_params(names), needs)
    if not configure:
        print(report(rows))
        autopilot = shell.companion.driver.seen.autopilot
        print(range_report(shell.read_params(range_params(autopilot), RANGE_WAIT), autopilot))
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
    rows = check(shell.read_params(names), needs)
    if not failed and not differing(rows):
        print("the autopilot is set up for companion mode")
    print(report(rows))
    return 1 if failed or differing(rows) else 0
