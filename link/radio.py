"""Simulated radio: what a packet between a ground-station antenna and the robot goes through.

Log-distance path loss, the attenuation of every wall on the line of sight (from the world's segment queries),
spatially correlated log-normal shadowing, and a noise floor give an RSSI; a logistic curve around the receiver
sensitivity turns RSSI into a per-packet delivery probability; latency has a base and a jitter. Both directions
use the same geometry (a reciprocal channel) but draw their own packet fates. Seeded, so runs repeat exactly.

Latency varies but order does not: a SiK radio or an 802.11 link delivers each direction first in, first out (a
packet that drew a short latency waits behind the one sent before it), so a chunked STATUSTEXT or a mission
transfer never arrives tail first. ``reorder`` lets a scenario ask for a network that does reorder.

The parameters can express the DARPA SubT virtual radio (log-distance exponent 2.5, 40 dB at 1 m, 10 dB log-normal
spread, -90 dBm noise floor; its 20 dBm transmit power is the station's ``power_dbm``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

MOTION_GRAIN = 0.05  # m


@dataclass(frozen=True)
class RadioParams:
    ref_loss_db: float = 40.0  # path loss at 1 m (2.4 GHz free space is ~40 dB)
    exponent: float = 2.2
    shadowing_db: float = 3.0
    shadowing_corr_m: float = 3.0
    noise_floor_dbm: float = -95.0
    sensitivity_dbm: float = -90.0  # 50 % delivery
    fade_width_db: float = 3.0
    latency_ms: float = 20.0
    jitter_ms: float = 5.0
    reorder: bool = False  # let per-packet jitter reorder packets (a routed network); off: first in, first out


@dataclass(frozen=True)
class LinkState:
    rssi_dbm: float
    noise_dbm: float
    delivery: float  # probability a packet gets through


def rssi_to_radio_status(rssi_dbm: float) -> int:
    """RADIO_STATUS rssi as SiK radios report it: 0..254 (dBm = value / 1.9 - 127), 255 = unknown."""
    return int(max(0, min(254, round((rssi_dbm + 127.0) * 1.9))))


class Radio:
    def __init__(self, params: RadioParams, attenuation: Callable[[tuple[float, float], tuple[float, float]], float],
                 seed: int) -> None:
        self.p = params
        self.attenuation = attenuation
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self._cells: dict[tuple[int, int], float] = {}
        self._last: dict[tuple, tuple[tuple[float, float], LinkState]] = {}
        self._lane_last: dict[object, float] = {}  # per direction: when its last packet arrives
        self.sent = 0
        self.lost = 0

    def _cell(self, i: int, j: int) -> float:
        v = self._cells.get((i, j))
        if v is None:
            v = float(np.random.default_rng([self.seed, i & 0xFFFFFFFF, j & 0xFFFFFFFF]).normal())
            self._cells[(i, j)] = v
        return v

    def _shadowing(self, x: float, y: float) -> float:
        """A fixed random field over the ground, correlated over ``shadowing_corr_m``: bilinear value noise.

        It must be a function of place, not of the path travelled, or a robot that backtracks to where the link
        was good would find a different channel there; real shadowing comes from the terrain and stays put.
        """
        c = self.p.shadowing_corr_m
        gx, gy = x / c, y / c
        i, j = math.floor(gx), math.floor(gy)
        u, v = gx - i, gy - j
        su, sv = u * u * (3 - 2 * u), v * v * (3 - 2 * v)  # smoothstep: no creases at cell edges
        top = self._cell(i, j) * (1 - su) + self._cell(i + 1, j) * su
        bottom = self._cell(i, j + 1) * (1 - su) + self._cell(i + 1, j + 1) * su
        # bilinear blending shrinks the spread between grid points; scale it back to roughly shadowing_db
        return self.p.shadowing_db * 1.4 * (top * (1 - sv) + bottom * sv)

    def link(self, antenna: tuple[float, float], power_dbm: float, robot: tuple[float, float]) -> LinkState:
        """Channel state between an antenna and the robot; call once per control tick. The channel is evaluated
        on a 5 cm grain of the robot's motion (shadowing decorrelates over metres), so a robot standing still or
        creeping does not repeat the wall queries every tick."""
        key = (antenna, power_dbm)
        hit = self._last.get(key)
        if hit is not None and abs(hit[0][0] - robot[0]) < MOTION_GRAIN and abs(hit[0][1] - robot[1]) < MOTION_GRAIN:
            return hit[1]
        state = self._link(antenna, power_dbm, robot)
        self._last[key] = ((robot[0], robot[1]), state)
        return state

    def _link(self, antenna: tuple[float, float], power_dbm: float, robot: tuple[float, float]) -> LinkState:
        d = max(1.0, math.hypot(robot[0] - antenna[0], robot[1] - antenna[1]))
        loss = self.p.ref_loss_db + 10.0 * self.p.exponent * math.log10(d)
        loss += self.attenuation(antenna, robot)
        rssi = power_dbm - loss + self._shadowing(*robot)
        snr_margin = rssi - max(self.p.sensitivity_dbm, self.p.noise_floor_dbm + 5.0)
        delivery = 1.0 / (1.0 + math.exp(-snr_margin / max(1e-6, self.p.fade_width_db / 4.0)))
        return LinkState(rssi, self.p.noise_floor_dbm, delivery)

    def packet(self, state: LinkState) -> float | None:
        """The fate of one packet: its latency in seconds, or None if it is lost."""
        self.sent += 1
        if self.rng.random() >= state.delivery:
            self.lost += 1
            return None
        return max(0.0, self.p.latency_ms + self.rng.normal(0.0, self.p.jitter_ms)) / 1000.0

    def arrival(self, state: LinkState, t: float, lane: object) -> float | None:
        """When a packet sent at ``t`` one way (``lane``, e.g. (source, destination)) arrives, or None if lost.

        Unless ``reorder`` is set, it never arrives before the packet sent before it in the same lane."""
        latency = self.packet(state)
        if latency is None:
            return None
        at = t + latency
        if not self.p.reorder:
            at = max(at, self._lane_last.get(lane, at))
            self._lane_last[lane] = at
        return at
