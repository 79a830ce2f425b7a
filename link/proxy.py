"""The radio between ground stations and the vehicle, in real time: a UDP relay that applies the radio model.

Every datagram either way is delivered or lost by ``link.radio.Radio`` for the robot's current position, and
held back by its latency and jitter; the radio also reports RADIO_STATUS to the ground stations once a second,
as a SiK telemetry radio does. ``returnlink sim serve`` puts it between its UDP socket and the simulated
vehicle, so MAVSDK, MAVProxy or QGroundControl feel the link die inside the tunnel.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable

from link import dialect
from link.radio import LinkState, Radio, rssi_to_radio_status
from link.transports import Address, UdpTransport

RADIO_SYSID, RADIO_COMPID = 51, 68  # what SiK telemetry radios use for their RADIO_STATUS


class RadioReport:
    """RADIO_STATUS frames as the ground-side telemetry radio sends them (rssi/remrssi, noise/remnoise)."""

    def __init__(self) -> None:
        self._mav = dialect.load().MAVLink(None, RADIO_SYSID, RADIO_COMPID)

    def frame(self, state: LinkState, jammed: bool = False, lost: int = 0) -> bytes:
        rssi = 0 if jammed else rssi_to_radio_status(state.rssi_dbm)
        noise = rssi_to_radio_status(state.noise_dbm)
        return self._mav.radio_status_encode(rssi, rssi, 100, noise, noise, 0, lost % 65536).pack(self._mav)


class RadioProxy:
    def __init__(self, transport: UdpTransport, radio: Radio | None, antenna: tuple[float, float],
                 power_dbm: float, robot: Callable[[], tuple[float, float]]) -> None:
        self.transport = transport
        self.radio = radio
        self.antenna, self.power_dbm, self.robot = antenna, power_dbm, robot
        self.state: LinkState | None = None
        self._up: list[tuple[float, int, bytes, Address]] = []  # to the vehicle
        self._down: list[tuple[float, int, bytes]] = []  # to the ground stations
        self._seq = itertools.count()
        self._report = RadioReport()
        self._next_status = 0.0
        self.lost = 0

    def update(self, t: float) -> None:
        """The channel for the robot's position now; call once per tick."""
        if self.radio is not None:
            self.state = self.radio.link(self.antenna, self.power_dbm, self.robot())

    def _fate(self, t: float, lane: str) -> float | None:
        """Arrival time of a datagram sent at ``t`` toward ``lane`` ("up" or "down"); the radio keeps each
        direction's order, so the heap releases them as sent."""
        if self.radio is None or self.state is None:
            return t
        at = self.radio.arrival(self.state, t, lane)
        if at is None:
            self.lost += 1
        return at

    def from_ground(self, t: float) -> list[tuple[bytes, Address]]:
        """Datagrams from the ground stations that reach the vehicle by ``t``, with the address each came from."""
        for data, addr in self.transport.receive():
            at = self._fate(t, "up")
            if at is not None:
                heapq.heappush(self._up, (at, next(self._seq), data, addr))
        out = []
        while self._up and self._up[0][0] <= t:
            _, _, data, addr = heapq.heappop(self._up)
            out.append((data, addr))
        return out

    def to_ground(self, data: bytes, t: float) -> None:
        at = self._fate(t, "down")
        if at is not None:
            heapq.heappush(self._down, (at, next(self._seq), data))

    def flush(self, t: float) -> None:
        """Send what is due to the ground stations, and the radio's own RADIO_STATUS once a second."""
        while self._down and self._down[0][0] <= t:
            self.transport.send(heapq.heappop(self._down)[2])
        if self.state is not None and t >= self._next_status:
            self._next_status = t + 1.0
            self.transport.send(self._report.frame(self.state, lost=self.lost))
