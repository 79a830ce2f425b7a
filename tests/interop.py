"""Shared helpers for the interop tests: a real-time simulated vehicle on loopback UDP, in a thread."""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from sim.scenario import load
from sim.serve import Server
from vehicle.keystore import KeyStore


def free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class ServedVehicle:
    """``returnlink sim serve`` in-process: the same Server class, a perfect link, loopback only."""

    def __init__(self, scenario: str = "tunnel", gcs_port: int | None = None, speedup: float = 1.0,
                 key_file=None) -> None:
        """``key_file``: start it as ``sim serve --key FILE`` would."""
        self.gcs_port = gcs_port or free_udp_port()
        keystore = KeyStore.open(key_file) if key_file is not None else None
        self.server = Server(load(scenario), port=0, peers=(("127.0.0.1", self.gcs_port),), perfect_link=True,
                             keystore=keystore)
        self.port = self.server.address[1]
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, args=(speedup,), daemon=True)
        self.thread.start()

    def _run(self, speedup: float) -> None:
        try:
            self.server.serve(speedup, stop=self._stop.is_set, out=None)
        except BaseException as e:  # noqa: BLE001 - surfaced by close() so a crash fails the test
            self.error = e

    @property
    def vehicle(self):
        return self.server.vehicle

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5)
        self.server.close()
        if self.error is not None:
            raise self.error


def wait_until(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    """Until ``predicate`` holds; ``timeout`` (wall-clock s) is a hang guard, never a speed check: the callers give
    20 s, since a 5 s wait for MAVSDK's flight mode ran out once while the other test worker kept both cores busy."""
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, f"timed out after {timeout} s waiting for {what}"
        time.sleep(0.05)


class MAVProxy:
    """The real MAVProxy (the pip package, headless, reading commands on stdin) against a served vehicle; its
    console goes to ``log``. ``modules`` None keeps MAVProxy's default module set. Stopped by its own process."""

    def __init__(self, gcs_port: int, tmp_path: Path, modules: str | None = None) -> None:
        exe = shutil.which("mavproxy.py") or str(Path(sys.executable).with_name("mavproxy.py"))
        self.log = tmp_path / "mavproxy.txt"
        extra = [] if modules is None else [f"--default-modules={modules}"]
        self.proc = subprocess.Popen(
            [sys.executable, exe, f"--master=udpin:127.0.0.1:{gcs_port}", "--dialect=returnlink",
             "--state-basedir", str(tmp_path), *extra],
            stdin=subprocess.PIPE, stdout=self.log.open("w"), stderr=subprocess.STDOUT, text=True, cwd=tmp_path)

    def say(self, command: str) -> None:
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def text(self) -> str:
        return self.log.read_text()

    def wait_for_parameters(self, count: int, timeout: float = 30.0) -> None:
        wait_until(lambda: f"Received {count} parameters" in self.text(), timeout, "MAVProxy to fetch the parameters")

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait(5)
