"""``returnlink sim serve``: the simulated vehicle in real time (or K times faster) over UDP, like other SITLs.

It binds a UDP port, sends to 127.0.0.1:14550 (QGroundControl, MAVProxy) and :14540 (MAVSDK) and answers whoever
talks to it, through the radio proxy so the link dies where the scenario says it does. On exit it writes a
trajectory plot of what happened.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from link.proxy import RadioProxy
from link.radio import Radio
from link.signing import stamp_from_unix
from link.transports import UdpTransport
from sim.driver import simulated_vehicle
from sim.plots import draw_trail, draw_world, plt, save
from sim.scenario import Scenario
from vehicle.core import DT, run
from vehicle.epochs import EpochLog
from vehicle.keystore import KeyStore


class Server:
    def __init__(self, scenario: Scenario, vehicle: str | None = None, seed: int | None = None,
                 port: int = 14580, peers: tuple[tuple[str, int], ...] = (("127.0.0.1", 14550), ("127.0.0.1", 14540)),
                 perfect_link: bool = False, param_file: Path | None = None, keystore: KeyStore | None = None,
                 epochs_file: Path | None = None) -> None:
        """``keystore`` (``KeyStore.open(FILE)``): the vehicle signs with that key and obeys only frames signed with
        it; its signing clock is the wall clock, as ground stations' are. ``epochs_file``: where the epochs this
        vehicle issues are kept across restarts (docs/architecture.md §3.1); the boot epoch is drawn from the OS random
        source either way, never from ``seed``."""
        sc = self.scenario = scenario
        self.kind = vehicle or sc.vehicle
        self.seed = sc.seed if seed is None else seed
        self.epochs = EpochLog(epochs_file)
        self.driver, self.vehicle, self.endpoint = simulated_vehicle(
            sc, self.kind, self.seed, param_file, self.epochs.boot, keystore=keystore,
            stamp=lambda t: stamp_from_unix(time.time()))
        self.vehicle.on_epoch = self.epochs.issued
        self.transport = UdpTransport(("127.0.0.1", port), peers, pinned=self.endpoint.pinned)
        station = sc.station(sc.operator_station)
        radio = None if perfect_link else Radio(sc.radio, self.driver.world.attenuation_db, self.seed + 1)
        self.proxy = RadioProxy(self.transport, radio, (station.x, station.y), station.power_dbm,
                                lambda: self.driver.pose[:2])
        self.true: list[tuple[float, float]] = []
        self.est: list[tuple[float, float]] = []

    @property
    def address(self) -> tuple[str, int]:
        return self.transport.address

    def _receive(self, t: float) -> list[tuple[bytes, tuple[str, int]]]:
        self.proxy.flush(t)
        return self.proxy.from_ground(t)

    def _send(self, frame: bytes, t: float) -> None:
        """Into the radio, and out at once if the radio says it is due by now (a perfect link, docs/architecture.md §8:
        a COMMAND_ACK leaves in the tick its command was received). Flushing only at the next tick's start held every
        reply back a whole tick (20 ms at 50 Hz) on top of the radio's own latency."""
        self.proxy.to_ground(frame, t)
        self.proxy.flush(t)

    def _after_tick(self, t: float) -> None:
        """Physics between vehicle ticks, the channel for the new position, a trace for the plot."""
        self.driver.advance(DT)
        self.proxy.update(t)
        if int(round(t / DT)) % 10 == 0:
            x, y, _ = self.driver.pose
            p = self.vehicle.estimator.pose
            self.true.append((x, y))
            self.est.append((p.x, p.y))
        if self._out is not None and t >= self._next_report:
            self._next_report = t + self._report_every
            p = self.vehicle.estimator.pose
            st = self.proxy.state
            link = "perfect" if st is None else f"{st.rssi_dbm:6.1f} dBm, delivery {st.delivery:4.2f}"
            print(f"t={t:7.1f} s  state {self.endpoint.custom_mode():#010x}  owner {self.vehicle.book.owner}"
                  f"  pos ({p.x:6.1f}, {p.y:6.1f})  link {link}", file=self._out, flush=True)

    def serve(self, speedup: float = 1.0, duration: float = float("inf"), stop=lambda: False,
              report_every: float = 5.0, out=sys.stderr, clock=time.monotonic, sleep=time.sleep,
              wait=None) -> None:
        """Run until ``duration`` simulated seconds or ``stop()``; ``clock``, ``sleep`` and ``wait`` are injectable
        so a test paces the loop in simulated time. On the real clock the loop waits on the UDP socket between
        ticks (``wait`` None) and answers a command as soon as it arrives."""
        self._out, self._report_every, self._next_report = out, report_every, 0.0
        run(self.vehicle, self.endpoint, self._receive, self._send, clock=clock, sleep=sleep, speedup=speedup,
            stop=lambda: self.vehicle.t >= duration or stop(), after_tick=self._after_tick,
            wait=self.transport.ready if wait is None and clock is time.monotonic else wait)

    def close(self) -> None:
        self.endpoint.close()  # the signing timestamp to disk
        self.transport.close()

    def plot(self, path: Path) -> Path:
        fig, ax = plt.subplots(figsize=(9, 7))
        draw_world(ax, self.driver.world, self.scenario.bounds)
        if self.true:
            true, est = np.array(self.true), np.array(self.est)
            ax.plot(true[:, 1], true[:, 0], color="k", lw=0.9, alpha=0.55, label="true path")
            ax.plot(est[:, 1], est[:, 0], color="tab:orange", lw=0.9, label="estimated path")
        draw_trail(ax, self.vehicle.trail.points(), self.vehicle.trail.link_good())
        ax.legend(loc="best", fontsize=7)
        ax.set_title(f"sim serve {self.scenario.name} ({self.kind}), {self.vehicle.t:.0f} s")
        return save(fig, path)
