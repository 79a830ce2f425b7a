"""What every autopilot process a run starts shares (the ArduPilot SITL, ``sim.firmware.process``; PX4,
``sim.px4.process``): a work directory of its own, removed when it stops unless it was given; its log, copied out
before the directory goes when the caller wants to keep it; start and stop as a context manager. How each is started
and how it is made to stop (one process, or a process group) stays with its module."""

from __future__ import annotations

import contextlib
import shutil
import socket
import subprocess
from pathlib import Path


def port_free(kind: int, port: int) -> bool:
    """Whether 127.0.0.1:``port`` can be bound for ``kind`` (SOCK_STREAM or SOCK_DGRAM) now."""
    s = socket.socket(socket.AF_INET, kind)
    try:
        s.bind(("127.0.0.1", port))
        return True
    except OSError:
        return False
    finally:
        s.close()


class WorkdirChild:
    """The shared lifecycle; a subclass sets ``workdir``, ``_own_dir``, ``log_path`` and ``proc`` and defines
    ``start`` and ``stop`` (which ends with ``_leave``)."""

    workdir: Path
    _own_dir: bool
    log_path: Path
    proc: subprocess.Popen | None

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def _leave(self, keep_log: Path | None) -> None:
        """After the process has ended: its log to ``keep_log`` (best effort), then the directory goes."""
        if keep_log is not None and self.log_path.is_file():
            with contextlib.suppress(OSError):
                keep_log.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(self.log_path, keep_log)
        self._remove_dir()

    def _remove_dir(self) -> None:
        if self._own_dir:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def start(self):  # noqa: ANN201 - each subclass returns itself
        raise NotImplementedError

    def stop(self, keep_log: Path | None = None) -> int | None:
        raise NotImplementedError

    def __enter__(self):  # noqa: ANN204
        return self.start() if self.proc is None else self

    def __exit__(self, *exc) -> None:
        self.stop()
