"""Starting and stopping one firmware process (docs/architecture.md §10).

Each run gets its own temporary directory (the firmware writes ``eeprom.bin`` and ``logs/`` where it runs; ``-w``
wipes stored parameters, so nothing leaks from one run to the next) and its own instance number ``-I N``, which adds
10·N to every port the firmware uses. The instance is claimed by binding the JSON physics port 9002+10·N ourselves
(the bridge needs that socket anyway): a bound port cannot be claimed twice, so parallel trials on one machine
never share one, and the firmware's other ports of that instance are checked free before it starts.

Stopping is by process id, SIGTERM then SIGKILL: with its physics gone the firmware sits in its resend loop and
ignores SIGTERM (measured), so a SIGTERM alone would leave it running. The child also gets SIGKILL from the kernel
if the thread that started it dies (``PR_SET_PDEATHSIG``), so a worker killed from outside, with no chance to run
its clean-up, still takes its firmware with it; and every live process is stopped at interpreter exit. No firmware
process outlives its run.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import os
import signal
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from sim.child import WorkdirChild, port_free

JSON_PORT = 9002  # + 10·instance: where the firmware sends its servo packets (we bind it)
SIM_IN_PORT = 9003  # + 10·instance: the firmware's own end of the JSON link
SERIAL_TCP_PORTS = (5760, 5762, 5763)  # + 10·instance: SERIAL0-2 listen here by default
RC_IN_PORT = 5501  # + 10·instance
MAX_INSTANCE = 199
# the first instance number to try, where a machine shared with other SITL users reserves a range for this checkout
# (else one derived from the process id); a number taken is still skipped, so this only says where to start
INSTANCE_ENV = "RETURNLINK_FIRMWARE_INSTANCE"
STOP_GRACE_S = 0.2  # how long SIGTERM gets before SIGKILL
_PR_SET_PDEATHSIG = 1

_live: set[FirmwareProcess] = set()


class FirmwareError(RuntimeError):
    """The firmware could not be started, died, restarted, or never became ready; the message says which."""


def claim_instance(start: int | None = None) -> tuple[int, socket.socket]:
    """An instance number and the bound JSON socket that reserves it. The search starts at ``start``, else at
    $RETURNLINK_FIRMWARE_INSTANCE, else at a place derived from the process id, so parallel workers rarely probe
    the same numbers first."""
    if start is None and os.environ.get(INSTANCE_ENV):
        text = os.environ[INSTANCE_ENV]
        if not text.isdigit() or int(text) > MAX_INSTANCE:
            raise FirmwareError(f"{INSTANCE_ENV}={text!r}: an instance number 0..{MAX_INSTANCE} is needed")
        start = int(text)
    # instance 0 is the one a person's own SITL and ground station use (TCP 5760, what the README's walkthrough
    # starts): a search from the process id never takes it, only an explicit start does
    lowest = 0 if start is not None else 1
    span = MAX_INSTANCE + 1 - lowest
    first = lowest + os.getpid() % span if start is None else start
    for k in range(span):
        n = lowest + (first - lowest + k) % span
        off = 10 * n
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind(("127.0.0.1", JSON_PORT + off))
        except OSError:
            sock.close()
            continue
        others = [(socket.SOCK_STREAM, p + off) for p in SERIAL_TCP_PORTS]
        others += [(socket.SOCK_DGRAM, SIM_IN_PORT + off), (socket.SOCK_DGRAM, RC_IN_PORT + off)]
        if all(port_free(kind, port) for kind, port in others):
            return n, sock
        sock.close()
    raise FirmwareError("no free firmware instance: every port set 0..199 is in use on this machine")


def _die_with_parent() -> None:
    """In the child, before exec: SIGKILL when the starting thread dies (Linux; elsewhere nothing)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)


class FirmwareProcess(WorkdirChild):
    """One running firmware: ``start`` it, read ``pid``, ``stop`` it (idempotent). A context manager."""

    def __init__(self, binary: Path, instance: int, args: list[str], workdir: Path | None = None) -> None:
        self.binary = Path(binary)
        self.instance = instance
        self.args = list(args)
        self._own_dir = workdir is None
        self.workdir = Path(tempfile.mkdtemp(prefix=f"returnlink-fw{instance}-")) if workdir is None else workdir
        self.log_path = self.workdir / "firmware.log"
        self.proc: subprocess.Popen | None = None

    @property
    def command(self) -> list[str]:
        return [str(self.binary), *self.args, "-I", str(self.instance)]

    def start(self) -> FirmwareProcess:
        self.workdir.mkdir(parents=True, exist_ok=True)
        with open(self.log_path, "wb") as log:
            try:
                self.proc = subprocess.Popen(self.command, cwd=self.workdir, stdin=subprocess.DEVNULL, stdout=log,
                                             stderr=subprocess.STDOUT, preexec_fn=_die_with_parent,
                                             start_new_session=True)
            except OSError as e:
                self._remove_dir()
                raise FirmwareError(f"cannot start {self.binary}: {e.strerror or e}") from None
        _live.add(self)
        return self

    def log_tail(self, lines: int = 8) -> str:
        try:
            text = self.log_path.read_text(errors="replace")
        except OSError:
            return ""
        return "\n".join(text.strip().splitlines()[-lines:])

    def stop(self, keep_log: Path | None = None) -> int | None:
        """SIGTERM, a short wait, SIGKILL; then the directory goes (its log copied to ``keep_log`` first).
        Returns the exit status (negative: the signal that ended it)."""
        proc = self.proc
        status = None
        if proc is not None:
            if proc.poll() is None:
                try:
                    proc.send_signal(signal.SIGTERM)
                    proc.wait(timeout=STOP_GRACE_S)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
                except ProcessLookupError:
                    pass
            status = proc.returncode
        _live.discard(self)
        self._leave(keep_log)
        return status


@contextlib.contextmanager
def stop_on_terminate() -> Iterator[None]:
    """While inside: SIGTERM (and SIGHUP) raise KeyboardInterrupt, as Ctrl-C does, so the run unwinds through its
    ``finally`` and stops its firmware, instead of dying with the child still running."""
    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.signal(s, interrupt) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


@atexit.register
def _stop_all() -> None:
    for fw in list(_live):
        fw.stop()


def wait_for(pid: int, timeout: float) -> bool:
    """True once process ``pid`` no longer exists (for tests and the CLI's own checks)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.02)
    return False
