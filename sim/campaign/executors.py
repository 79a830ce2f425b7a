"""Where trials run: in this process one after another (``SerialExecutor``), or on Ray (``RayExecutor``), the
only module that imports ray.

Both are context managers with the same ``map(trials, timeout_s)`` that yields one row per trial as trials finish,
in any order. Neither ever raises because of a trial: a trial that raises, runs past ``timeout_s`` or takes its
worker down becomes a row with status ``error`` and the reason, and the campaign goes on.

On Ray, trials are Ray tasks: Ray keeps each worker process alive between tasks, so the simulator is imported
once per worker, not once per trial. A worker that dies (killed, out of memory, a lost node) has its trial run
again once (``max_retries=1``). The timeout is enforced twice: inside the worker by an alarm signal, which ends
the trial cleanly and keeps the worker, and from the driver by cancelling (killing) a task that is still running
well past it, for a trial stuck where the alarm cannot reach it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator

from sim.campaign.trial import Trial, error_row, run_trial

TrialFn = Callable[[Trial], dict]
OBJECT_STORE_BYTES = 96 * 1024**2  # rows are a few kB: Ray's default (30 % of RAM) would only slow start-up
HARD_KILL_GRACE_S = 15.0  # after the in-worker alarm should have fired; covers a worker's first imports too
POLL_S = 0.5


class TrialTimeout(BaseException):
    """Raised into a trial by the alarm. A BaseException, so a trial's own ``except Exception`` cannot swallow
    it."""


@contextlib.contextmanager
def _alarm(seconds: float) -> Iterator[None]:
    """Raise TrialTimeout after ``seconds`` of wall-clock time, where signals can be used (the main thread of a
    POSIX process); elsewhere only the driver's hard limit applies."""
    usable = hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
    if not usable:
        yield
        return

    def ring(_sig, _frame):
        raise TrialTimeout

    old = signal.signal(signal.SIGALRM, ring)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def timed_out(trial: Trial, timeout_s: float) -> dict:
    return error_row(trial, f"timed out after {timeout_s:g} s (wall clock)")


def guarded(fn: TrialFn, trial: Trial, timeout_s: float) -> dict:
    """``fn(trial)`` within the time limit; whatever it raises is the trial's error row."""
    try:
        with _alarm(timeout_s):
            return fn(trial)
    except TrialTimeout:
        return timed_out(trial, timeout_s)
    except Exception as e:  # noqa: BLE001 - one trial's failure is its row, never the end of the sweep
        return error_row(trial, f"{type(e).__name__}: {e}")


def _token_auth_if_available() -> None:
    """Speak token authentication to a cluster when this machine has a Ray token, as `ray start` does.

    A local ``ray.init()`` leaves a token in ~/.ray/auth_token, and every later ``ray start --head`` on the machine
    then requires it; but Ray only sends it on its own for ``address="auto"``, not for an explicit HOST:PORT. So
    with no RAY_AUTH_MODE chosen by the user, a token present means token mode (set before Ray is imported, as Ray
    reads it once). A cluster without authentication accepts a token too.
    """
    if "RAY_AUTH_MODE" in os.environ:
        return
    path = os.environ.get("RAY_AUTH_TOKEN_PATH") or os.path.join(os.path.expanduser("~"), ".ray", "auth_token")
    if os.environ.get("RAY_AUTH_TOKEN") or os.path.isfile(path):
        os.environ["RAY_AUTH_MODE"] = "token"


class SerialExecutor:
    """Trials one after another in this process: for tests and for debugging a single trial."""

    workers = 1
    where = "this process"

    def __enter__(self) -> SerialExecutor:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def map(self, trials: Iterable[Trial], timeout_s: float, fn: TrialFn = run_trial) -> Iterator[dict]:
        for t in trials:
            yield guarded(fn, t, timeout_s)


class RayExecutor:
    """Trials as Ray tasks, at most ``workers`` at a time.

    With no ``address`` a private local Ray is started for this command (loopback only, no dashboard, a small
    object store, usage statistics off) and stopped on exit. With ``"auto"`` or ``"HOST:PORT"`` an existing
    cluster is joined (``ray start --head`` ...), and left running on exit; its nodes need returnlink installed.
    """

    def __init__(self, workers: int | None = None, address: str | None = None) -> None:
        self.address = address
        self.workers = workers
        self.where = ""
        self._ray = None
        self._remote = None

    def __enter__(self) -> RayExecutor:
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # offline: no usage report
        if self.address:
            _token_auth_if_available()
        import ray

        common = {"log_to_driver": False, "logging_level": logging.ERROR}
        if self.address:
            ray.init(address=self.address, **common)
        else:
            # "local": a new private instance, even where `ray start` left a cluster address behind
            ray.init(address="local", num_cpus=self.workers or os.cpu_count() or 1, include_dashboard=False,
                     object_store_memory=OBJECT_STORE_BYTES, _node_ip_address="127.0.0.1", **common)
        self._ray = ray
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.workers = self.workers or max(1, cpus)
        self.where = f"Ray at {self.address} ({cpus} CPUs)" if self.address else f"a local Ray ({cpus} CPUs)"
        self._remote = ray.remote(num_cpus=1, max_retries=1, retry_exceptions=False)(guarded)
        return self

    def __exit__(self, *exc) -> None:
        if self._ray is not None:
            self._ray.shutdown()
            self._ray = None

    def map(self, trials: Iterable[Trial], timeout_s: float, fn: TrialFn = run_trial) -> Iterator[dict]:
        ray = self._ray
        assert ray is not None, "use RayExecutor as a context manager"
        todo = iter(trials)
        running: dict = {}  # ref -> (trial, submitted at)
        cancelled: set = set()
        hard_limit = timeout_s + HARD_KILL_GRACE_S
        exhausted = False
        while running or not exhausted:
            while not exhausted and len(running) < self.workers:
                t = next(todo, None)
                if t is None:
                    exhausted = True
                    break
                running[self._remote.remote(fn, t, timeout_s)] = (t, time.monotonic())
            if not running:
                break
            ready, _ = ray.wait(list(running), num_returns=1, timeout=POLL_S)
            for ref in ready:
                t, _t0 = running.pop(ref)
                try:
                    yield ray.get(ref)
                except ray.exceptions.TaskCancelledError:
                    yield timed_out(t, timeout_s)
                except ray.exceptions.RayError as e:
                    yield timed_out(t, timeout_s) if ref in cancelled else error_row(
                        t, f"worker lost twice: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}")
                cancelled.discard(ref)
            now = time.monotonic()
            for ref, (_t, t0) in running.items():
                if ref not in cancelled and now - t0 > hard_limit:
                    ray.cancel(ref, force=True)
                    cancelled.add(ref)
