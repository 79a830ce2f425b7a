"""``returnlink sim serve``: a scenario flown in real time (or K times faster) over UDP, for ground stations of your
own, like other SITLs; whatever flies it.

One real-time loop for every plant (``sim.plants``: returnlink's vehicle on a pymunk robot, the ArduPilot firmware
alone, with its Lua applet or with returnlink companion beside it, PX4 alone or with the companion): the lockstep
loop (``sim.runner.Run``) paced to the wall clock, with the same plants and the same tick order, chosen the same way
(``sim.runner.plant_for``). Only what surrounds the plant differs: no scripted stations and no timed events (you
are the operator); the radio proxy (``link.proxy.RadioProxy``) carries the plant's frames to whoever talks to the
UDP port (and to 127.0.0.1:14550 and :14540 before anyone does) and theirs to the plant, so the link dies where
the scenario says.

Pacing: after each tick the loop waits until the wall clock has caught up with ``t / speedup`` (a machine too slow
for the pace runs behind it, never ahead). Meanwhile it serves the link: what arrives is handed to the plant at
once and its answers (``Plant.replies``) leave then, as autopilots service their links faster than their control
loop, so a COMMAND_ACK leaves in the tick its command was received (docs/architecture.md §8), not a tick later.
An autopilot that paces itself (the ArduPilot firmware at ``speedup``) rarely leaves anything to wait for.

A plant that carries returnlink (``Plant.leases``: the native vehicle, the companion) boots as a vehicle on a robot
does (``served_boot``): its parameter file, the epochs it issued kept across restarts (the boot epoch drawn from
the operating system's random source, never from the seed), and with a key its signing clock the wall clock.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

from link.proxy import RadioProxy
from link.radio import Radio
from link.signing import stamp_from_unix
from link.transports import UdpTransport
from sim.plants import Plant
from sim.policies import DEFAULT_POLICY
from sim.runner import frozen, plant_for
from sim.scenario import Scenario
from vehicle.epochs import EpochLog
from vehicle.keystore import KeyStore

DEFAULT_PEERS = (("127.0.0.1", 14550), ("127.0.0.1", 14540))  # QGroundControl and MAVProxy; MAVSDK
PATH_EVERY = 10  # ticks between two points of the served path kept for the plot (5 Hz: bounded over hours)


def served_boot(epochs: EpochLog, param_file: Path | None, keystore: KeyStore | None) -> dict:
    """What a served returnlink vehicle (the native one or the companion) boots with, as a plant's options: the
    parameter file it boots from and saves to, the boot epoch drawn by ``epochs`` and where it records each one it
    issues, the key it signs with and, since ground stations stamp with it, the wall clock as its signing clock."""
    return {"param_file": param_file, "boot_epoch": epochs.boot, "on_epoch": epochs.issued, "keystore": keystore,
            "stamp": lambda t: stamp_from_unix(time.time())}


class WallPace:
    """Simulated time held to the wall clock: ``hold(t)`` returns once the wall has reached tick ``t``'s moment
    (``t / speedup`` after the first tick's), calling ``between()`` whenever ``wait`` says input is ready before it.
    ``clock``, ``sleep`` and ``wait`` are injected, so a test paces in simulated time."""

    def __init__(self, speedup: float, clock: Callable[[], float], sleep: Callable[[float], None],
                 wait: Callable[[float], bool] | None) -> None:
        if not (math.isfinite(speedup) and speedup > 0):
            raise ValueError(f"speedup must be a positive number, got {speedup!r}")
        self.speedup, self.clock, self.sleep, self.wait = speedup, clock, sleep, wait
        self.wall0: float | None = None

    def mark(self, t: float) -> None:
        """Tick ``t`` is starting: the first one sets where simulated time 0 lies on the wall."""
        if self.wall0 is None:
            self.wall0 = self.clock() - t / self.speedup

    def hold(self, t: float, between: Callable[[], None]) -> None:
        due = self.wall0 + t / self.speedup
        remaining = due - self.clock()
        while remaining > 0:
            if self.wait is None:
                self.sleep(remaining)
                return
            if not self.wait(remaining):  # nothing came: the next tick is due (or the link failed: sleep instead)
                remaining = due - self.clock()
                if remaining > 0:
                    self.sleep(remaining)
                return
            between()
            remaining = due - self.clock()


class Server:
    """One scenario flown in real time by one plant (see the module docstring): ``plant`` chosen by
    ``sim.runner.plant_for`` from the vehicle and the policy, or given; ``options`` go to it (the firmware's
    ``firmware=PATH``, ``log_path`` and ``speedup``, PX4's ``px4=PATH``). ``param_file``, ``keystore`` and
    ``epochs_file`` are what a plant carrying returnlink keeps (``served_boot``). ``serve()`` flies it until its
    duration or ``stop()``; ``close()`` releases the UDP port."""

    def __init__(self, scenario: Scenario, vehicle: str | None = None, seed: int | None = None, port: int = 14580,
                 peers: tuple[tuple[str, int], ...] = DEFAULT_PEERS, perfect_link: bool = False,
                 param_file: Path | None = None, keystore: KeyStore | None = None, epochs_file: Path | None = None,
                 policy: str = DEFAULT_POLICY, plant: type | None = None, **options) -> None:
        self.scenario = sc = scenario
        self.seed = sc.seed if seed is None else seed
        self.policy = policy
        plant_type = plant or plant_for(vehicle or sc.vehicle, policy)
        if plant_type.leases:
            options = {**served_boot(EpochLog(epochs_file), param_file, keystore), **options}
        elif param_file is not None or keystore is not None or epochs_file is not None:
            raise ValueError(f"{plant_type.__name__} carries no returnlink to keep parameters, a key or epochs for")
        self.plant: Plant = plant_type(sc, vehicle or sc.vehicle, self.seed, policy, **options)
        self.kind = self.plant.kind
        self.world, self.robot = self.plant.world, self.plant.robot
        self.metrics: dict | None = None  # nothing is judged: what a plot's title reads
        self.transport = UdpTransport(("127.0.0.1", port), peers, pinned=self.plant.pinned)
        station = sc.station(sc.operator_station)
        radio = None if perfect_link else Radio(sc.radio, self.world.attenuation_db, self.seed + 1)
        self.proxy = RadioProxy(self.transport, radio, (station.x, station.y), station.power_dbm,
                                lambda: self.robot.pose[:2])
        self.t = 0.0
        self.ticks = 0
        # (true x, true y, estimated x, estimated y), every PATH_EVERY ticks, in the true frame: the trajectory's
        # path where the plant keeps no rows of its own; a served run keeps no lease record (``sim.report.Run``)
        self.path: list[tuple[float, float, float, float]] = []
        self.trace = None
        self.blocks: list = []
        self.losses: list = []
        self.link_backs: list = []
        self._out = None
        self._report_every = 5.0
        self._next_report = 0.0
        self._next_radio_status = 0.0
        self._pace: WallPace | None = None
        self._stop: Callable[[], bool] = lambda: False
        self._plant_closed = False

    @property
    def address(self) -> tuple[str, int]:
        return self.transport.address

    @property
    def vehicle(self):
        """returnlink's vehicle aboard the plant (None: an autopilot alone, or a companion not booted yet)."""
        return self.plant.vehicle

    # ----- the loop ------------------------------------------------------------------------------------------
    def serve(self, speedup: float = 1.0, duration: float = math.inf, stop: Callable[[], bool] = lambda: False,
              report_every: float = 5.0, out=sys.stderr, clock: Callable[[], float] = time.monotonic,
              sleep: Callable[[float], None] = time.sleep, wait: Callable[[float], bool] | None = None) -> Server:
        """Every tick until ``duration`` simulated seconds or ``stop()``, a status line to ``out`` (None: quiet)
        every ``report_every`` simulated s. On the real clock the loop waits on the UDP socket between ticks
        (``wait`` None) and answers what arrives at once. Whatever the plant runs outside this process is stopped
        however the loop ends (the objects alive before it frozen out of garbage collection meanwhile, as in a
        lockstep run: ``sim.runner.frozen``)."""
        self._pace = WallPace(speedup, clock, sleep,
                              self.transport.ready if wait is None and clock is time.monotonic else wait)
        self._stop, self._out, self._report_every, self._next_report = stop, out, report_every, 0.0
        with frozen():
            try:
                self.plant.start()
                if out is not None and (words := self.plant.started()):
                    print(f"returnlink: {words}", file=out, flush=True)
                self.plant.pace(self._paced, duration)
            finally:
                self._close_plant()
        return self

    def close(self) -> None:
        """The plant closed if ``serve`` has not closed it yet (what it keeps goes to disk: the signing timestamp),
        and the UDP port released."""
        self._close_plant()
        self.transport.close()

    def _close_plant(self) -> None:
        if not self._plant_closed:
            self._plant_closed = True
            self.plant.close()

    def _paced(self, t: float) -> bool:
        """The tick at ``t``, then the wait for the wall clock; False once ``stop()`` says so."""
        self._pace.mark(t)
        self._tick(t)
        self._pace.hold(t, lambda: self._between(t))
        return not self._stop()

    def _tick(self, t: float) -> None:
        """One tick in the lockstep loop's order: the plant hears what the radio delivered and ticks (before the
        ground's radio leg, or after it when ``hears_last``); the channel follows the true pose; the plant's frames
        go out through the radio; RADIO_STATUS; the record."""
        self.t = t
        self.ticks += 1
        plant, proxy = self.plant, self.proxy
        if not plant.hears_last:
            self._hear(t)
            plant.tick(t)
        proxy.update(t)
        for data in plant.frames(t):
            proxy.to_ground(data, t)
        proxy.flush(t)
        if plant.hears_last:
            self._hear(t)
            plant.tick(t)
        self._radio_status(t)
        self._record(t)

    def _hear(self, t: float) -> None:
        """What the radio has delivered by ``t`` (due frames out first), to the plant with where it came from."""
        self.proxy.flush(t)
        frames = self.proxy.from_ground(t)
        if frames:
            self.plant.receive(frames, t)

    def _between(self, t: float) -> None:
        """Input before the next tick: handled now, at this tick's time, and answered at once (into the radio, and
        out if it is due by now: on a perfect link, at once)."""
        self._hear(t)
        for data in self.plant.replies():
            self.proxy.to_ground(data, t)
        self.proxy.flush(t)

    def _radio_status(self, t: float) -> None:
        """Once a second the vehicle-side radio reports the operator station's channel to the plant, as a SiK radio
        does (nothing on a perfect link: no radio)."""
        state = self.proxy.state
        if state is not None and t >= self._next_radio_status:
            self._next_radio_status = t + 1.0
            self.plant.radio_status(state, t)

    def _record(self, t: float) -> None:
        """The plant's own row of the tick, a point of the served path now and then, and a status line every
        ``report_every`` simulated s."""
        x, y, _ = self.robot.pose
        state = self.proxy.state
        link, rssi = (1.0, math.nan) if state is None else (state.delivery, state.rssi_dbm)
        plant = self.plant
        if plant.rows is not None:
            plant.record(t, (x, y), link, rssi)
        if self.ticks % PATH_EVERY == 0:
            self.path.append((x, y, *plant.estimate()))
        if self._out is not None and t >= self._next_report:
            self._next_report = t + self._report_every
            quality = "perfect" if state is None else f"{state.rssi_dbm:6.1f} dBm, delivery {state.delivery:4.2f}"
            print(f"t={t:7.1f} s{plant.status()}  pos ({x:6.1f}, {y:6.1f})  link {quality}", file=self._out,
                  flush=True)
