"""``returnlink companion`` as a process, and ground stations talking to it over loopback UDP on the wall clock.

A ``LiveStation`` is the project's own ground-station library (``gcs.station.GroundStation``) on a UDP socket, with
a loss model: ``reach()`` says whether the radio carries its traffic now (both ways), so a test can take the
station out of range and bring it back where the rover comes within it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from gcs.station import GroundStation


class CompanionProcess:
    """The command line itself, started by the test and stopped by its own pid."""

    def __init__(self, args: list[str], workdir: Path) -> None:
        self.log = workdir / "companion.log"
        exe = Path(sys.executable).with_name("returnlink")
        self.proc = subprocess.Popen([str(exe), "companion", *args], cwd=workdir, stdout=self.log.open("w"),
                                     stderr=subprocess.STDOUT, start_new_session=True)

    def text(self) -> str:
        return self.log.read_text()

    def kill(self) -> None:
        """As a crash would: SIGKILL, no goodbye."""
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.wait(5)

    def stop(self) -> int | None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                os.kill(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        return self.proc.returncode


class LiveStation:
    """A ground station on its own UDP port; the companion (``--gcs udpout:127.0.0.1:PORT``) talks to the first,
    others reach it by writing to the address the first learned."""

    def __init__(self, sysid: int, target_comp: int = 191, peer: tuple[str, int] | None = None) -> None:
        self.gs = GroundStation(sysid, 190, target=1, target_comp=target_comp)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.peer = peer
        self.reach: Callable[[], bool] = lambda: True
        self.t0 = time.monotonic()
        self.velocity: tuple[float, float] | None = None  # a body-frame target streamed to the autopilot at 10 Hz
        self.next_velocity = 0.0

    def send_autopilot(self, build) -> None:
        """One message built by ``build(mav)`` (for the autopilot, component 1), through this station's encoder."""
        self.gs.mav.send(build(self.gs.mav))

    def pump(self) -> None:
        t = time.monotonic() - self.t0
        reach = self.reach()
        while True:
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                break
            self.peer = self.peer or addr
            if reach:
                self.gs.feed(data, t)
        if self.velocity is not None and t >= self.next_velocity:
            self.next_velocity = t + 0.1
            vx, yaw_rate = self.velocity
            self.send_autopilot(lambda m: m.set_position_target_local_ned_encode(
                0, 1, 1, 8, 0b0000_0101_1100_0111, 0, 0, 0, vx, 0, 0, 0, 0, 0, 0, yaw_rate))
        frames = self.gs.tick(t)
        if reach and self.peer is not None:
            for f in frames:
                self.sock.sendto(f, self.peer)

    def close(self) -> None:
        self.sock.close()


def pump(parts: list, seconds: float, until: Callable[[], bool] | None = None, what: str = "") -> bool:
    """Serve every station and the firmware's observer at about 50 Hz for ``seconds``, or until ``until()``."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for p in parts:
            p.pump() if hasattr(p, "pump") else p.watch()
        if until is not None and until():
            return True
        time.sleep(0.02)
    if until is None:
        return False
    assert until(), f"timed out after {seconds} s waiting for {what}"
    return True


@contextlib.contextmanager
def firmware_companion(tmp_path):
    """The firmware booted, the companion on its SERIAL1, and the owner's station the companion sends to: yields
    (firmware, companion, owner) once the owner hears the companion's LEASE_STATUS, and stops all three after."""
    from tests.ardurover import Firmware

    fw = Firmware(tmp_path)
    owner = LiveStation(255)
    comp = None
    try:
        fw.boot()
        comp = CompanionProcess(["--autopilot", f"tcp:127.0.0.1:{fw.serial1}", "--gcs",
                                 f"udpout:127.0.0.1:{owner.port}", "--params", str(tmp_path / "companion.parm")],
                                tmp_path)
        pump([owner, fw], 30, lambda: owner.gs.vehicle.status is not None, "the companion's LEASE_STATUS")
        yield fw, comp, owner
    finally:
        if comp is not None:
            comp.stop()
        owner.close()
        fw.stop()
