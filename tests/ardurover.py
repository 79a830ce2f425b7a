"""The real ArduPilot Rover firmware (SITL) for tests, one process per test in its own directory.

Where the firmware is: ``RETURNLINK_ARDUROVER``, else ``ardurover`` on PATH. With neither, the firmware tests skip
and say why; with the variable set, a missing or broken binary fails them (CI sets it, and a test that cannot run
there must not pass by skipping).

The firmware runs its own physics (``--model rover``). It boots at ten times real time with SERIAL0 listening
without waiting (``--serial0 tcp:0``); once its EKF uses GPS the observer on SERIAL0 sets SIM_SPEEDUP to 1, because
the companion and the ground stations run on the wall clock: a keepalive at 1 Hz of wall time would be a keepalive
every 10 s of the firmware's, and its failsafe would fire. The companion then connects to SERIAL1, a telemetry
port like the one a companion computer is wired to. The observer never sends a heartbeat and its system id (200) is
outside the firmware's ground-station range: it keeps nothing alive, it only watches.
"""

from __future__ import annotations

import math
import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from sim.firmware.process import claim_instance

ENV = "RETURNLINK_ARDUROVER"
TEST_PARAMS = {
    "FS_THR_ENABLE": 0,  # SITL has no RC receiver: no radio failsafe at boot
    "FS_GCS_ENABLE": 1,  # the companion's backstop (what --configure sets)
    "FS_GCS_TIMEOUT": 3,
    "FS_ACTION": 2,  # Hold
}
BOOT_SPEEDUP = 10


def firmware() -> Path:
    """The firmware binary, or skip (none anywhere) / fail (``RETURNLINK_ARDUROVER`` names a bad one)."""
    named = os.environ.get(ENV)
    if named:
        p = Path(named)
        if not p.is_file() or not os.access(p, os.X_OK):
            pytest.fail(f"{ENV}={named} is not an executable file")
        return p
    found = shutil.which("ardurover")
    if found is None:
        pytest.skip(f"no ArduPilot Rover firmware: set {ENV} to an ardurover SITL binary (or put one on PATH) "
                    f"to run the tests against the real firmware")
    return Path(found)


class Firmware:
    """One ArduRover SITL process (instance ``instance``: ports 5760 + 10 * instance and up), stopped by pid.

    The instance is claimed as the simulator's runs claim theirs (``claim_instance``: its ports free, its JSON port
    held until ``stop``), so tests never collide with each other or with anything else using SITL ports here."""

    def __init__(self, workdir: Path, params: dict[str, float] | None = None) -> None:
        self.exe = firmware()
        self.dir = workdir
        instance, self.reservation = claim_instance()
        self.instance = instance
        self.serial0 = 5760 + 10 * instance
        self.serial1 = 5762 + 10 * instance
        parm = workdir / "test.parm"
        parm.write_text("".join(f"{k} {v}\n" for k, v in {**TEST_PARAMS, **(params or {})}.items()))
        defaults = [str(p) for p in (self.exe.with_name("rover.parm"), parm) if p.is_file()]
        self.log = workdir / "firmware.log"
        self.proc = subprocess.Popen(
            [str(self.exe), "--model", "rover", "-w", "--defaults", ",".join(defaults), "-I", str(instance),
             "--speedup", str(BOOT_SPEEDUP), "--serial0", "tcp:0"],
            cwd=workdir, stdout=self.log.open("w"), stderr=subprocess.STDOUT, start_new_session=True)
        self.observer: mavutil.mavfile | None = None
        self.mode: int | None = None
        self.armed = False
        self.position: tuple[float, float] | None = None
        self.speed = 0.0
        self.clock: float | None = None  # s: the firmware's own time (time_boot_ms of its last message stamped)
        self.texts: list[str] = []

    def boot(self, timeout: float = 60.0) -> None:
        """Wait for the EKF to use GPS, then run at real time."""
        end = time.monotonic() + timeout
        while self.observer is None:
            self._alive()
            try:
                socket.create_connection(("127.0.0.1", self.serial0), timeout=1).close()
                self.observer = mavutil.mavlink_connection(f"tcp:127.0.0.1:{self.serial0}", source_system=200,
                                                           source_component=1, dialect="ardupilotmega", retries=0)
            except OSError:
                assert time.monotonic() < end, f"the firmware never listened on tcp {self.serial0}"
                time.sleep(0.2)
        o = self.observer
        assert o.wait_heartbeat(timeout=10) is not None, "no heartbeat from the firmware"
        for msgid, us in ((193, 200_000), (32, 100_000), (0, 1_000_000)):
            o.mav.command_long_send(1, 1, 511, 0, msgid, us, 0, 0, 0, 0, 0)
        ready = False
        while not ready:
            self._alive()
            assert time.monotonic() < end, f"the firmware's EKF never used GPS; see {self.log}"
            m = o.recv_match(type="EKF_STATUS_REPORT", blocking=True, timeout=1)
            ready = m is not None and bool(m.flags & 16)
        o.mav.param_set_send(1, 1, b"SIM_SPEEDUP", 1.0, 9)
        while True:
            assert time.monotonic() < end, "SIM_SPEEDUP was not set"
            m = o.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
            if m is not None and m.param_id == "SIM_SPEEDUP" and m.param_value == 1.0:
                break
            o.mav.param_set_send(1, 1, b"SIM_SPEEDUP", 1.0, 9)

    def _alive(self) -> None:
        code = self.proc.poll()
        assert code is None, f"the firmware exited with {code}; see {self.log}: {self.log.read_text()[-800:]}"

    def watch(self) -> None:
        """Take what the observer has received (non-blocking): mode, armed, position, speed, texts, and the
        firmware's own clock from the time_boot_ms it stamps on its messages (tests time on it, never on ours)."""
        o = self.observer
        if o is None:
            return
        while True:
            m = o.recv_msg()
            if m is None:
                return
            kind = m.get_type()
            boot_ms = getattr(m, "time_boot_ms", None)
            if boot_ms is not None and m.get_srcComponent() == 1:
                self.clock = boot_ms / 1000
            if kind == "HEARTBEAT" and m.get_srcComponent() == 1 and m.autopilot != 8:
                self.mode, self.armed = m.custom_mode, bool(m.base_mode & 128)
            elif kind == "LOCAL_POSITION_NED":
                self.position, self.speed = (m.x, m.y), math.hypot(m.vx, m.vy)
            elif kind == "STATUSTEXT":
                self.texts.append(m.text)

    def distance(self) -> float:
        return math.hypot(*self.position) if self.position is not None else 0.0

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after a short wait (a firmware with nothing to talk to may ignore SIGTERM)."""
        if self.observer is not None:
            self.observer.close()
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(2)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        self.reservation.close()  # the instance is free again once its firmware is gone
