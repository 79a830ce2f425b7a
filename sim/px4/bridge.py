"""The TCP server PX4's simulator link connects to, one ``step`` per physics step (docs/architecture.md §10.1).

PX4 is the client: at boot its simulator_mavlink module connects to TCP 4560+i and waits until something listens
there. We listen on that port from the moment the instance is claimed (``process.claim_instance`` binds it), so
the connection waits in the listen queue until ``accept``. MAVLink 2, dialect common (pymavlink's); PX4 sends as
its own system id on that link, with HIL_ACTUATOR_CONTROLS the only message the bridge uses (it also sends a
HEARTBEAT at start and asks for HIL_STATE_QUATERNION, which a sensor-level simulator does not send).

Lockstep, the physics owns time: each ``step(state, dt)`` sends HIL_SENSOR stamped with the simulated time (PX4
sets its clock from it and runs its modules up to that time), HIL_GPS when due, then reads whatever
HIL_ACTUATOR_CONTROLS arrived and returns the newest; the rover drives on the last command until a newer one
comes, as a real rover does between two control updates. Between steps the sensor stream is PX4's only clock:
no HIL_SENSOR, no time passes in PX4.

Pacing: PX4 has no back-pressure of its own. Its receive thread sets the clock from each HIL_SENSOR as it comes;
a simulator that sends faster than PX4's modules run leaves them behind a clock that has moved on (at boot, while
rcS still starts modules in wall time, that ends in "BARO #0 failed: STALE" and an EKF2 without data: measured).
So the bridge paces itself on how far PX4 has got, from two sources: the stamp of each HIL_ACTUATOR_CONTROLS
(PX4's clock when its controllers had run: 100 Hz, but only while armed, as rover_differential publishes no
motor commands disarmed), and, when the caller has one, ``clock``: PX4's time as its MAVLink links report it
(``time_boot_ms`` of ATTITUDE and the like on the GCS link the simulator loop reads anyway), with ``watch`` the
sockets that bring it. A step waits, at most ``wait_s`` wall time at once, while PX4 trails the physics by more
than ``max_lag_us``. With neither source alive (at boot, or disarmed without a ``clock``) the bridge runs at
``free_rtf`` times real time, 1 by default: what PX4 always keeps up with.
"""

from __future__ import annotations

import select
import socket
import time
from collections.abc import Callable, Sequence

import numpy as np
from pymavlink.dialects.v20 import common as mav

from link.mission import Origin
from sim.px4.hil import (
    ALL_SENSORS,
    GpsClock,
    RoverState,
    SensorNoise,
    Wheels,
    earth_field,
    hil_gps,
    hil_sensor,
    wheels,
)
from sim.robots import normal_draws

SIM_SYSID, SIM_COMPID = 1, 51  # the simulator's own voice on the HIL link (PX4 does not check it)
ACCEPT_TIMEOUT_S = 60.0  # wall seconds PX4 gets to boot up to its simulator link
SEND_TIMEOUT_S = 10.0  # wall seconds PX4 may leave the link's buffer full before it counts as hung
WAIT_S = 0.005  # the most one step waits for PX4 to catch up
MAX_LAG_US = 30_000  # how far PX4's clock may trail the physics before a step waits (its answers come every 10 ms)
STALE_S = 0.2  # wall seconds without news of PX4's clock before the bridge stops waiting for it and runs free
FREE_RTF = 1.0  # the pace without news: real time, which PX4 keeps up with even while rcS still starts modules
NO_WHEELS = Wheels(0.0, 0.0, 0, False)
NOISE = SensorNoise()  # on every run unless a caller asks for exact sensors (noise=None)


class BridgeError(RuntimeError):
    """PX4 never connected, or its link closed; the message says which."""


class HilBridge:
    """PX4's simulator link for one rover: ``accept`` the connection, then ``step`` once per physics step;
    ``close`` (always, in a ``finally``). ``server`` is the listening socket from ``claim_instance``; ``clock``
    (optional) returns the newest PX4 time in µs the caller has seen on another link, or None, reading the
    ``watch`` sockets without blocking."""

    def __init__(self, server: socket.socket, origin: Origin | None = None, start_usec: int = 1000,
                 clock: Callable[[], int | None] | None = None, watch: Sequence[socket.socket] = (),
                 wait_s: float = WAIT_S, max_lag_us: int = MAX_LAG_US, free_rtf: float = FREE_RTF,
                 noise: SensorNoise | None = NOISE, seed: int = 0) -> None:
        self.server = server
        self.origin = origin or Origin()
        self.field = earth_field(self.origin.lat, self.origin.lon)
        self.time_usec = start_usec
        self.clock, self.watch = clock, list(watch)
        self.wait_s, self.max_lag_us, self.free_rtf = wait_s, max_lag_us, free_rtf
        self.gps = GpsClock()
        self.noise = noise
        self.normal = normal_draws(np.random.default_rng(seed)).__next__  # the sensor noise's own stream
        self.conn: socket.socket | None = None
        self.mav = mav.MAVLink(None, srcSystem=SIM_SYSID, srcComponent=SIM_COMPID)
        self.rx = mav.MAVLink(None)
        self.rx.robust_parsing = True
        self.wheels = NO_WHEELS  # the newest HIL_ACTUATOR_CONTROLS
        self.answers = 0  # how many arrived
        self.px4_usec: int | None = None  # the newest PX4 time known, from either source, and when it came (wall)
        self._news_at = 0.0
        self._free: tuple[float, int] | None = None  # (wall, sim µs) where the free pace started
        # where the wall time went, for the real-time factor's account: waiting for PX4, sleeping at the free pace
        self.waits, self.waited_s, self.free_s = 0, 0.0, 0.0

    def accept(self, timeout: float = ACCEPT_TIMEOUT_S, alive: Callable[[], bool] | None = None) -> None:
        """Wait for PX4 to connect (``alive()``, if given, is asked every 0.2 s: a PX4 that died is not waited
        for the whole timeout)."""
        deadline = time.monotonic() + timeout
        while True:
            ready, _, _ = select.select([self.server], [], [], 0.2)
            if ready:
                self.conn, _ = self.server.accept()
                break
            if alive is not None and not alive():
                raise BridgeError("PX4 exited before it connected to the simulator link")
            if time.monotonic() > deadline:
                raise BridgeError(f"PX4 did not connect to the simulator link within {timeout:g} s")
        self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.conn.setblocking(False)

    def close(self) -> None:
        for s in (self.conn, self.server):
            if s is not None:
                s.close()
        self.conn = None

    def step(self, state: RoverState, dt: float, extra: Sequence = ()) -> Wheels:
        """Send the sensors for ``state`` at the bridge's clock (and the GPS when due, and the ``extra`` messages:
        the rover's distance sensors), keep pace with PX4, move the clock on by ``dt``, and return PX4's newest wheel
        commands (zeros until it has sent any)."""
        t = self.time_usec
        sensors = hil_sensor(state, t, self.field, self.origin.alt, ALL_SENSORS, self.noise, self.normal)
        out = sensors.pack(self.mav)
        if self.gps.due(t):
            out += hil_gps(state, t, self.origin).pack(self.mav)
        for m in extra:
            out += m.pack(self.mav)
        self._send(out)
        self._read()
        self._pace(t)
        self.time_usec = t + round(dt * 1e6)
        return self.wheels

    def _news(self, now: float) -> None:
        """Take in the newest PX4 time from the answers and from ``clock``."""
        known = self.wheels.time_usec if self.answers else None
        if self.clock is not None:
            c = self.clock()
            if c is not None and (known is None or c > known):
                known = c
        if known is not None and (self.px4_usec is None or known > self.px4_usec):
            self.px4_usec, self._news_at = known, now

    def _pace(self, t: int) -> None:
        now = time.perf_counter()
        self._news(now)
        if self.px4_usec is not None and now - self._news_at < STALE_S:
            self._free = None
            if t - self.px4_usec > self.max_lag_us:
                self._wait(t, now)
            return
        if self._free is None:
            self._free = (now, t)
        ahead = (t - self._free[1]) / 1e6 / self.free_rtf - (now - self._free[0])
        if ahead > 0:
            time.sleep(ahead)
            self.free_s += ahead

    def _wait(self, t: int, start: float) -> None:
        """Wait, at most ``wait_s``, until PX4's clock is within ``max_lag_us`` of ``t``."""
        deadline = start + self.wait_s
        self.waits += 1
        watched = [self.conn, *self.watch]
        now = start
        while t - self.px4_usec > self.max_lag_us and now < deadline:
            select.select(watched, [], [], deadline - now)
            self._read()
            now = time.perf_counter()
            self._news(now)
        self.waited_s += now - start

    def _send(self, data: bytes) -> None:
        """All of ``data`` on the non-blocking link (waiting for room only if PX4 stopped reading, which a
        live PX4 never does for long)."""
        view = memoryview(data)
        deadline = None
        while view:
            try:
                view = view[self.conn.send(view):]
            except BlockingIOError:
                deadline = deadline or time.monotonic() + SEND_TIMEOUT_S
                if time.monotonic() > deadline:
                    raise BridgeError(f"PX4 read nothing from the simulator link for {SEND_TIMEOUT_S:g} s") from None
                select.select([], [self.conn], [], 0.1)
            except OSError as e:
                raise BridgeError(f"the simulator link to PX4 broke: {e}") from None

    def _read(self) -> None:
        while True:
            try:
                data = self.conn.recv(65536)
            except BlockingIOError:
                return
            except OSError as e:
                raise BridgeError(f"the simulator link to PX4 broke: {e}") from None
            if not data:
                raise BridgeError("PX4 closed the simulator link")
            for msg in self.rx.parse_buffer(data) or ():
                if msg.get_msgId() == mav.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS:
                    self.wheels = wheels(msg)
                    self.answers += 1
