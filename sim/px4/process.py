"""Starting and stopping one PX4 SITL process (docs/architecture.md §10.1).

Each run gets a fresh temporary directory: ``rootfs/`` is PX4's working directory (``-w``: parameters, dataman, logs;
nothing leaks from one run to the next) and ``bin/`` holds symlinks of our own, ``px4`` to the real binary and
``px4-<module>`` to ``px4``. PX4's start-up script runs each command as such a ``px4-<module>`` client of the
server, found on PATH beside the binary it was started as; a copy of a build tree that lost its symlinks (a plain
file saying ``px4`` in their place, as shared/ has) cannot run them, so the run never relies on the tree's own.

The instance ``-i N`` moves every port PX4 uses by N: the simulator link connects to TCP 4560+N, the GCS link binds
UDP 18570+N, the API link 14580+N (payload 14280+N, gimbal 13030+N). The instance is claimed by listening on TCP
4560+N ourselves (the bridge needs that server socket anyway): a bound port cannot be claimed twice, so parallel
runs never share one; PX4's other ports of that instance, and its per-instance server lock ``/tmp/px4_lock-N``,
are checked free before it starts.

Where PX4 sends before anyone has talked to it is moved too. Its start-up script (``px4-rc.mavlink``) starts the
GCS link with no remote port, so it speaks to UDP 14550 (every ground station's port, a ``returnlink companion``
walkthrough's, a MAVProxy's) until a partner talks, and the API link to 14540+N (MAVSDK's). Each run lays its own
copy of that script in its ``bin/``, found first on PX4's search path, with ``-o`` naming ports of the run's own:
the GCS link's ``gcs_port`` (the caller's own socket, or 18470+N) and the API link's 18370+N. Nothing outside the
run hears it. A tree whose script lacks those lines runs with its own (``remote_ports`` then says None).

Parameters are preset through ``PX4_PARAM_<NAME>`` environment variables, which rcS applies with ``param set``
early; the SITL defaults and the airframe that come after only ``param set-default``, which never overrides a value
that was set, so ours win over both. (MAV_SYS_ID is set after them: it is always instance + 1.)

Stopping is by process group, SIGTERM then SIGKILL: PX4 runs its start-up script in a shell whose module commands
are client processes of the server, and while it waits for its simulator the server ignores SIGTERM (measured): it
waits on rcS, which waits on the ``px4-simulator_mavlink`` client. SIGTERM to the whole group ends the shell and the
client, and with them the server; whatever is left after a short grace gets SIGKILL. The group is its own session
(``start_new_session``), so killing it reaches nothing else; the server also gets SIGKILL from the kernel if the
thread that started it dies (``PR_SET_PDEATHSIG``), and every live PX4 is stopped at interpreter exit. No PX4
process outlives its run.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import fcntl
import os
import signal
import socket
import struct
import subprocess
import tempfile
import time
from pathlib import Path

from sim.child import WorkdirChild, port_free

SIM_TCP_PORT = 4560  # + instance: the simulator_mavlink link (PX4 is the client; we listen)
GCS_UDP_PORT = 18570  # + instance: PX4's GCS MAVLink link binds here
API_UDP_PORT = 14580  # + instance: PX4's offboard/API MAVLink link binds here
OTHER_UDP_PORTS = (14280, 13030)  # + instance: the payload and gimbal links bind these
GCS_REMOTE_PORT = 18470  # + instance: where PX4's GCS link speaks until a partner talks (PX4's own default: 14550)
API_REMOTE_PORT = 18370  # + instance: where its API link speaks until a partner talks (PX4's own: 14540+N)
MAVLINK_RC = "px4-rc.mavlink"  # the start-up script (etc/init.d-posix/) that starts PX4's MAVLink links
_GCS_START = "mavlink start -x -u $udp_gcs_port_local "  # the GCS link's start line, as PX4's script writes it
_API_REMOTE = "-o $udp_offboard_port_remote"  # the API link's remote port, as PX4's script writes it
MAX_INSTANCE = 99
INSTANCE_ENV = "RETURNLINK_PX4_INSTANCE"  # where to start looking for a free instance (a machine shared with others)
LOCK_FILE = "/tmp/px4_lock-{}"  # PX4's own per-instance server lock: held (fcntl) while a PX4 of that instance runs
MODEL = "hil_rover_differential"  # PX4_SIM_MODEL: selects airframe 1069 by name
STOP_GRACE_S = 1.0  # how long SIGTERM gets before SIGKILL
_PR_SET_PDEATHSIG = 1

# Parameters every run presets (a run's own go on top). Why each:
DEFAULT_PARAMS: dict[str, float] = {
    "COM_RC_IN_MODE": 4,  # stick input disabled: no RC is simulated, nothing waits for or fails over one
    "SDLOG_MODE": -1,  # no ulog: the logger costs CPU and disk at every step and nobody reads it here
}

_live: set[PX4Process] = set()


class PX4Error(RuntimeError):
    """PX4 could not be started, died, or never became ready; the message says which."""


def lock_held(instance: int) -> bool:
    """Whether a PX4 server of ``instance`` runs on this machine (it holds an fcntl lock on its lock file)."""
    try:
        fd = os.open(LOCK_FILE.format(instance), os.O_RDONLY)
    except OSError:
        return False  # no lock file: no PX4 of this instance ever ran here (or it was cleaned away)
    try:
        probe = struct.pack("hhllhh", fcntl.F_WRLCK, os.SEEK_SET, 0, 0, 0, 0)  # struct flock, as F_GETLK wants it
        answer = fcntl.fcntl(fd, fcntl.F_GETLK, probe)
        return struct.unpack("hhllhh", answer)[0] != fcntl.F_UNLCK
    except OSError:
        return True  # cannot tell: leave that instance alone
    finally:
        os.close(fd)


def claim_instance(start: int | None = None) -> tuple[int, socket.socket]:
    """An instance number and the listening TCP socket on 4560+N that reserves it (the bridge's server socket).
    The search starts at ``start``, else at $RETURNLINK_PX4_INSTANCE, else at a place derived from the process id,
    so parallel workers rarely probe the same numbers first."""
    if start is None and os.environ.get(INSTANCE_ENV):
        text = os.environ[INSTANCE_ENV]
        if not text.isdigit() or int(text) > MAX_INSTANCE:
            raise PX4Error(f"{INSTANCE_ENV}={text!r}: an instance number 0..{MAX_INSTANCE} is needed")
        start = int(text)
    first = os.getpid() % (MAX_INSTANCE + 1) if start is None else start
    for k in range(MAX_INSTANCE + 1):
        n = (first + k) % (MAX_INSTANCE + 1)
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            sock.bind(("127.0.0.1", SIM_TCP_PORT + n))
            sock.listen(1)
        except OSError:
            sock.close()
            continue
        udp = [GCS_UDP_PORT + n, API_UDP_PORT + n, *(p + n for p in OTHER_UDP_PORTS), GCS_REMOTE_PORT + n,
               API_REMOTE_PORT + n]
        if all(port_free(socket.SOCK_DGRAM, p) for p in udp) and not lock_held(n):
            return n, sock
        sock.close()
    raise PX4Error(f"no free PX4 instance: every port set 0..{MAX_INSTANCE} is in use on this machine")


def _die_with_parent() -> None:
    """In the child, before exec: SIGKILL when the starting thread dies (Linux; elsewhere nothing)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)


def module_names(px4_dir: Path) -> list[str]:
    """The ``px4-<module>`` client names the build provides (whatever form their entries in ``bin/`` took)."""
    return sorted(p.name for p in (Path(px4_dir) / "bin").glob("px4-*") if not p.name.endswith(".sh"))


def mavlink_rc(text: str, gcs_port: int, api_port: int) -> str | None:
    """PX4's ``px4-rc.mavlink`` with its GCS link speaking to ``gcs_port`` and its API link to ``api_port`` until a
    partner talks (``-o``); None if the script has no such lines to change (another PX4 version)."""
    lines = text.splitlines()
    gcs = [k for k, ln in enumerate(lines) if ln.startswith(_GCS_START) and " -o " not in ln]
    api = [k for k, ln in enumerate(lines) if _API_REMOTE in ln]
    if len(gcs) != 1 or len(api) != 1:
        return None
    lines[gcs[0]] += f" -o {gcs_port}"
    lines[api[0]] = lines[api[0]].replace(_API_REMOTE, f"-o {api_port}")
    return "\n".join(lines) + "\n"


def param_env(params: dict[str, float]) -> dict[str, str]:
    """``PX4_PARAM_<NAME>`` variables for ``params`` (integers written as integers: rcS hands the text to
    ``param set``, which parses an INT32 parameter's value as an integer)."""
    out = {}
    for name, value in params.items():
        text = str(int(value)) if float(value).is_integer() else repr(float(value))
        out[f"PX4_PARAM_{name}"] = text
    return out


class PX4Process(WorkdirChild):
    """One running PX4: ``start`` it, read ``pid``, ``stop`` it (idempotent). A context manager."""

    def __init__(self, px4_dir: Path, instance: int, params: dict[str, float] | None = None,
                 workdir: Path | None = None, gcs_port: int | None = None) -> None:
        self.px4_dir = Path(px4_dir)
        self.instance = instance
        self.gcs_port = GCS_REMOTE_PORT + instance if gcs_port is None else gcs_port
        self.remote_ports: tuple[int, int] | None = None  # (GCS, API) once laid out with our own script
        self.params = {**DEFAULT_PARAMS, **(params or {})}
        self._own_dir = workdir is None
        self.workdir = Path(tempfile.mkdtemp(prefix=f"returnlink-px4-{instance}-")) if workdir is None else workdir
        self.log_path = self.workdir / "px4.log"
        self.proc: subprocess.Popen | None = None

    @property
    def command(self) -> list[str]:
        return [str(self.workdir / "bin" / "px4"), "-i", str(self.instance), "-w", str(self.workdir / "rootfs"),
                str(self.px4_dir / "etc"), "-d"]

    def _lay_out(self) -> None:
        """``bin/`` of symlinks (the real binary, and each module client pointing at it) and an empty ``rootfs/``."""
        bin_dir = self.workdir / "bin"
        bin_dir.mkdir(parents=True, exist_ok=True)
        (self.workdir / "rootfs").mkdir(exist_ok=True)
        (bin_dir / "px4").symlink_to(self.px4_dir.resolve() / "bin" / "px4")
        alias = self.px4_dir / "bin" / "px4-alias.sh"
        if alias.is_file():
            (bin_dir / "px4-alias.sh").symlink_to(alias.resolve())
        for name in module_names(self.px4_dir):
            (bin_dir / name).symlink_to("px4")
        self._own_mavlink_rc(bin_dir)

    def _own_mavlink_rc(self, bin_dir: Path) -> None:
        """Our copy of PX4's MAVLink start-up script beside the module clients (rcS sources it by name from the
        search path, where ``bin/`` comes before ``etc/init.d-posix``), sending to this run's own ports."""
        try:
            text = (self.px4_dir / "etc" / "init.d-posix" / MAVLINK_RC).read_text()
        except OSError:
            return
        api_port = API_REMOTE_PORT + self.instance
        ours = mavlink_rc(text, self.gcs_port, api_port)
        if ours is not None:
            (bin_dir / MAVLINK_RC).write_text(ours)
            self.remote_ports = (self.gcs_port, api_port)

    def environment(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("PX4_")}  # nothing of another run's setup
        env.update(param_env(self.params))
        env["PX4_SIM_MODEL"] = MODEL
        return env

    def start(self) -> PX4Process:
        try:
            self._lay_out()
            with open(self.log_path, "wb") as log:
                self.proc = subprocess.Popen(self.command, cwd=self.workdir, env=self.environment(),
                                             stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                             preexec_fn=_die_with_parent, start_new_session=True)
        except OSError as e:
            self._remove_dir()
            raise PX4Error(f"cannot start PX4 from {self.px4_dir}: {e.strerror or e}") from None
        _live.add(self)
        return self

    def log_text(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def log_tail(self, lines: int = 12) -> str:
        return "\n".join(self.log_text().strip().splitlines()[-lines:])

    def _group_alive(self) -> bool:
        try:
            os.killpg(self.proc.pid, 0)
            return True
        except ProcessLookupError:
            return False
        except PermissionError:
            return True

    def _signal_group(self, sig: int) -> None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.proc.pid, sig)

    def stop(self, keep_log: Path | None = None) -> int | None:
        """SIGTERM to the whole group, a short wait, SIGKILL to what is left; then the directory goes (its log
        copied to ``keep_log`` first). Returns the server's exit status (negative: the signal that ended it)."""
        proc = self.proc
        status = None
        if proc is not None:
            if proc.poll() is None or self._group_alive():
                self._signal_group(signal.SIGTERM)
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=STOP_GRACE_S)
                deadline = time.monotonic() + 5.0
                while self._group_alive() and time.monotonic() < deadline:
                    self._signal_group(signal.SIGKILL)
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        proc.wait(timeout=0.05)
            proc.wait()
            status = proc.returncode
        _live.discard(self)
        self._leave(keep_log)
        return status


@atexit.register
def _stop_all() -> None:
    for p in list(_live):
        p.stop()
