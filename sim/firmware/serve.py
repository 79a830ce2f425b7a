"""``returnlink sim serve SCENARIO --vehicle ardurover``: the real ArduPilot firmware in a scenario's world, in real
time (or K times faster), for a ground station of your own.

The firmware paces itself (``--speedup K``) and the bridge answers every servo packet as in a lockstep run; its
SERIAL0 reaches 127.0.0.1:14550 and :14540 (and whoever talks to the UDP port) through the same radio proxy the
native `sim serve` uses, so MAVProxy, MAVSDK or QGroundControl fly the firmware and feel the link die where the
scenario says. No scripted operator: you are the operator. On exit it writes the trajectory plot.

With ``--policy applet`` the firmware carries returnlink's Lua applet (``AppletServer``): the same script and RLNK_
parameters as a lockstep run, and the vehicle-side radio's RADIO_STATUS into the firmware's port once a second, so
the applet hears the link as it would on a rover with a SiK radio.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from link.proxy import RadioProxy
from link.radio import Radio
from link.transports import UdpTransport
from sim.firmware.lockstep import MODE_NAMES
from sim.plants.applet import AppletPlant
from sim.plants.firmware import FirmwarePlant
from sim.policies import FIRMWARE_VEHICLE
from sim.runner import frozen
from sim.scenario import Scenario


class FirmwareServer:
    """The firmware plant (``sim.plants.firmware``) behind the radio proxy instead of the lockstep loop's scripted
    stations: the plant's lockstep physics and pace, a loop of its own (no scenario clock, no operator)."""

    plant_type: type = FirmwarePlant

    def __init__(self, scenario: Scenario, seed: int | None, policy: str, firmware: Path, port: int = 14580,
                 peers: tuple[tuple[str, int], ...] = (("127.0.0.1", 14550), ("127.0.0.1", 14540)),
                 perfect_link: bool = False, speedup: float = 1.0, duration: float = math.inf,
                 log_path: Path | None = None, out=sys.stderr, **plant_options) -> None:
        self.scenario = scenario
        self.seed = scenario.seed if seed is None else seed
        self.policy = policy
        self.duration = duration
        self.speedup = speedup
        self.plant = self._make_plant(firmware, log_path, **plant_options)
        self.world, self.robot, self.link, self.rows = self.plant.world, self.plant.robot, self.plant.link, \
            self.plant.rows
        self.metrics: dict | None = None  # nothing is judged: what the plot's title reads
        self.transport = UdpTransport(("127.0.0.1", port), peers)
        st = scenario.station(scenario.operator_station)
        radio = None if perfect_link else Radio(scenario.radio, self.world.attenuation_db, self.seed + 1)
        self.proxy = RadioProxy(self.transport, radio, (st.x, st.y), st.power_dbm, lambda: self.robot.pose[:2])
        self.out = out
        self._next_report = 0.0

    def _make_plant(self, firmware: Path, log_path: Path | None, **plant_options):
        """The plant, pacing itself at ``speedup`` (the firmware keeps its own time)."""
        return self.plant_type(self.scenario, FIRMWARE_VEHICLE, self.seed, self.policy, firmware, log_path,
                               self.speedup, **plant_options)

    @property
    def address(self) -> tuple[str, int]:
        return self.transport.address

    def _boot(self) -> None:
        print("returnlink: the firmware is booting (its EKF needs a GPS fix first)...", file=self.out, flush=True)
        self.plant.start()
        tap = self.link.tap
        print(f"returnlink: {tap.version} ready after {self.link.boot_s:.1f} simulated s", file=self.out, flush=True)

    def _paced(self, t: float) -> bool:
        self._tick(t)
        return True

    def _tick(self, t: float) -> None:
        proxy = self.proxy
        proxy.update(t)
        for data in self.link.drain(t):
            proxy.to_ground(data, t)
        proxy.flush(t)
        for data, _addr in proxy.from_ground(t):
            self.link.send(data)
        self._record_tick(t)

    def _record_tick(self, t: float) -> None:
        """The tick's row for the plot, and every 5 simulated s a status line."""
        x, y, _ = self.robot.pose
        st = self.proxy.state
        link, rssi = (1.0, math.nan) if st is None else (st.delivery, st.rssi_dbm)
        mode = -1 if self.link.tap.mode is None else self.link.tap.mode
        self.rows.append((t, x, y, math.nan, math.nan, mode, link, rssi, *self.link.cmd, self.link.tap.armed,
                          self.world.collisions))
        if t >= self._next_report:
            self._next_report = t + 5.0
            quality = "perfect" if st is None else f"{st.rssi_dbm:6.1f} dBm, delivery {st.delivery:4.2f}"
            tap = self.link.tap
            names = getattr(self.plant, "mode_names", MODE_NAMES)
            print(f"t={t:7.1f} s  {names.get(tap.mode, '?'):<10} {'armed' if tap.armed else 'disarmed'}"
                  f"  pos ({x:6.1f}, {y:6.1f})  link {quality}{self._status()}", file=self.out, flush=True)

    def _status(self) -> str:
        """What else the status line says (the companion's lease)."""
        return ""

    def run(self) -> FirmwareServer:
        """Until ``duration`` or an interrupt; the firmware is stopped however it ends (the objects alive before
        frozen out of garbage collection meanwhile, as in a lockstep run: ``sim.runner.frozen``)."""
        try:
            with frozen():
                try:
                    self._boot()
                    self.plant.pace(self._paced, self.duration)
                finally:
                    self.plant.close()
        finally:
            self.transport.sock.close()
        return self


class AppletServer(FirmwareServer):
    """The firmware with returnlink's Lua applet aboard (``sim.plants.applet.AppletPlant``), served as above: the
    applet's returns and texts reach your ground station as they would from a rover."""

    plant_type: type = AppletPlant
    _next_radio = 0.0  # when the vehicle-side radio next reports

    def _tick(self, t: float) -> None:
        super()._tick(t)
        state = self.proxy.state
        if state is not None and t >= self._next_radio:  # the radio's report, once a second as a SiK radio sends it
            self._next_radio = t + 1.0
            self.plant.radio_status(state, t)
