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

Each random stream belongs to one subsystem, named, and is derived from the run's seed by that name
(``subsystem_rng``): the packet fates of one direction of one station's link (keyed by send time and rank, so
they do not depend on how many packets went before), the shadowing field, the sensors, the robot. A draw in one
never shifts another, so two trials that differ only in what the vehicle does after a link loss see the same
radio, sensors and physics until then (docs/architecture.md §9, paired trials).
"""

from __future__ import annotations

import hashlib
import math
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

MOTION_GRAIN = 0.05  # m
_US_RANK = struct.Struct("<qI").pack  # what a packet's fate hash reads: send time (µs) and rank at that time
_THREE_WORDS = struct.Struct("<QQQ").unpack


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


class _FateStream:
    """One link direction's packet fates: its keyed hash before any packet (keying BLAKE2b costs a whole
    compression of the key block, so each packet copies this state instead of keying a fresh one: the digest is
    the same), and the send time (µs) and rank of its last packet. One record, so a packet looks its direction up
    once."""

    __slots__ = ("hash", "us", "rank")

    def __init__(self, key: bytes) -> None:
        self.hash = hashlib.blake2b(digest_size=24, key=key)
        self.us: int | None = None
        self.rank = 0


class LinkState(NamedTuple):
    """The channel at one place. A named tuple rather than a frozen dataclass: the runner works one out whenever
    the robot has moved a few centimetres, and a tuple is built at a third of the cost, immutable all the same."""

    rssi_dbm: float
    noise_dbm: float
    delivery: float  # probability a packet gets through


def subsystem_seed(seed: int, name: str) -> np.random.SeedSequence:
    """The seed sequence of subsystem ``name`` in a run seeded ``seed``: the run's entropy with the name as its
    spawn key, so every subsystem gets an independent stream and adding one never moves the others."""
    return np.random.SeedSequence(seed, spawn_key=(zlib.crc32(name.encode("utf-8")),))


def subsystem_rng(seed: int, name: str) -> np.random.Generator:
    """A generator of its own for subsystem ``name`` (``radio.shadowing``, ``sensors``, ``robot``, ...)."""
    return np.random.default_rng(subsystem_seed(seed, name))


def rssi_to_radio_status(rssi_dbm: float) -> int:
    """RADIO_STATUS rssi as SiK radios report it: 0..254 (dBm = value / 1.9 - 127), 255 = unknown."""
    return int(max(0, min(254, round((rssi_dbm + 127.0) * 1.9))))


class Radio:
    def __init__(self, params: RadioParams, attenuation: Callable[[tuple[float, float], tuple[float, float]], float],
                 seed: int) -> None:
        self.p = params
        self.attenuation = attenuation
        self.seed = seed
        self.rng = subsystem_rng(seed, "radio.packets")  # the stream of callers that name none
        self._streams: dict[str, bytes] = {}  # the fate key of each link direction
        self._fates: dict[str, _FateStream] = {}  # each direction's keyed hash and last packet
        # the shadowing field is a function of place, seeded once from its own stream
        self._field_seed = int(subsystem_seed(seed, "radio.shadowing").generate_state(1)[0])
        self._cells: dict[tuple[int, int], float] = {}
        self._corners: dict[tuple[int, int], tuple[float, float, float, float]] = {}  # a grid square's 4 cells
        self._last: dict[tuple, tuple[float, float, LinkState]] = {}  # per antenna: where it was last worked out
        self._lane_last: dict[object, float] = {}  # per direction: when its last packet arrives
        self.sent = 0
        self.lost = 0

    def _cell(self, i: int, j: int) -> float:
        v = self._cells.get((i, j))
        if v is None:
            v = float(np.random.default_rng([self._field_seed, i & 0xFFFFFFFF, j & 0xFFFFFFFF]).normal())
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
        corners = self._corners.get((i, j))
        if corners is None:  # a robot stays in a grid square for many channel updates: look its corners up once
            corners = self._corners[(i, j)] = (self._cell(i, j), self._cell(i + 1, j), self._cell(i, j + 1),
                                               self._cell(i + 1, j + 1))
        c00, c10, c01, c11 = corners
        top = c00 * (1 - su) + c10 * su
        bottom = c01 * (1 - su) + c11 * su
        # bilinear blending shrinks the spread between grid points; scale it back to roughly shadowing_db
        return self.p.shadowing_db * 1.4 * (top * (1 - sv) + bottom * sv)

    def link(self, antenna: tuple[float, float], power_dbm: float, robot: tuple[float, float]) -> LinkState:
        """Channel state between an antenna and the robot; call once per control tick. The channel is evaluated
        on a 5 cm grain of the robot's motion (shadowing decorrelates over metres), so a robot standing still or
        creeping does not repeat the wall queries every tick."""
        key = (antenna, power_dbm)
        hit = self._last.get(key)
        x, y = robot[0], robot[1]
        if hit is not None:
            hx, hy, state = hit
            # (``abs(hx - x) < MOTION_GRAIN`` as a chained comparison: the same test, without a call)
            if -MOTION_GRAIN < hx - x < MOTION_GRAIN and -MOTION_GRAIN < hy - y < MOTION_GRAIN:
                return state
        state = self._link(antenna, power_dbm, robot)
        self._last[key] = (x, y, state)
        return state

    def _link(self, antenna: tuple[float, float], power_dbm: float, robot: tuple[float, float]) -> LinkState:
        d = max(1.0, math.hypot(robot[0] - antenna[0], robot[1] - antenna[1]))
        loss = self.p.ref_loss_db + 10.0 * self.p.exponent * math.log10(d)
        loss += self.attenuation(antenna, robot)
        rssi = power_dbm - loss + self._shadowing(*robot)
        snr_margin = rssi - max(self.p.sensitivity_dbm, self.p.noise_floor_dbm + 5.0)
        # (the exponent clamped: behind a few rock walls the margin is hundreds of dB down, and exp overflows; past
        # +-700 the delivery is 0 or 1 to the last bit anyway)
        z = min(700.0, max(-700.0, -snr_margin / max(1e-6, self.p.fade_width_db / 4.0)))
        delivery = 1.0 / (1.0 + math.exp(z))
        return LinkState(rssi, self.p.noise_floor_dbm, delivery)

    def _fate_key(self, name: str) -> bytes:
        key = self._streams.get(name)
        if key is None:
            words = subsystem_seed(self.seed, f"radio.{name}").generate_state(4)
            key = self._streams[name] = words.tobytes()
        return key

    def _uniforms(self, name: str, t: float) -> tuple[float, float, float]:
        """Three uniforms in (0, 1) for the next packet of stream ``name`` sent at time ``t``: a hash of the
        stream's key, the time (µs) and the packet's rank among that stream's packets at that time. A packet's
        fate depends on nothing sent before it, so two runs that differ only in extra traffic (a longer return
        plan, a baseline's telemetry after the loss) still see the same fates for the packets they share."""
        us = round(t * 1e6)  # (an int: ``round`` of a float with no digits)
        f = self._fates.get(name)
        if f is None:
            f = self._fates[name] = _FateStream(self._fate_key(name))
        if f.us == us:
            f.rank += 1
        else:
            f.us, f.rank = us, 0
        h = f.hash.copy()
        h.update(_US_RANK(us, f.rank))
        a, b, c = _THREE_WORDS(h.digest())
        return (a + 0.5) / 2.0**64, (b + 0.5) / 2.0**64, (c + 0.5) / 2.0**64

    def packet(self, state: LinkState, stream: str | None = None, t: float | None = None) -> float | None:
        """The fate of one packet: its latency in seconds, or None if it is lost.

        With ``stream`` (a link direction such as ``uplink.gcs``) and the send time ``t``, the fate is drawn
        from that direction's own key (see ``_uniforms``); without them, from one sequential stream shared by
        every caller (the real-time proxy, which has no lockstep time)."""
        self.sent += 1
        if stream is None or t is None:
            u, jitter = self.rng.random(), self.rng.normal()  # (both drawn: the shared stream's order)
        else:
            u, u1, u2 = self._uniforms(stream, t)
            jitter = None  # Box-Muller below, only for a packet that arrives
        if u >= state.delivery:
            self.lost += 1
            return None
        if jitter is None:
            jitter = math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)
        ms = self.p.latency_ms + self.p.jitter_ms * jitter
        return (ms if ms > 0.0 else 0.0) / 1000.0  # ``max(0.0, ms)`` (the same for every float), without a call

    def arrival(self, state: LinkState, t: float, lane: object, stream: str | None = None) -> float | None:
        """When a packet sent at ``t`` one way (``lane``, e.g. (source, destination)) arrives, or None if lost;
        ``stream`` names the direction's own random stream (see ``packet``).

        Unless ``reorder`` is set, it never arrives before the packet sent before it in the same lane."""
        latency = self.packet(state, stream, t if stream is not None else None)
        if latency is None:
            return None
        at = t + latency
        if not self.p.reorder:
            last = self._lane_last.get(lane)
            if last is not None and last > at:  # behind the lane's last packet: ``max(at, last)``
                at = last
            self._lane_last[lane] = at
        return at
