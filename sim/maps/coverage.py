"""The predicted link over a whole map from one station: mean RSSI and packet delivery at every free place.

The mean channel of ``link.radio`` (log-distance path loss, the grid's wall loss, no shadowing: the same for every
seed) at many points at once. Sampling each point's own line of sight would cost a line per point (10^5 points,
thousands of samples each); instead rays fan out from the station, close enough that neighbouring rays are at most
half a cell apart at the farthest point, each ray is marched once with running counts of solid runs crossed and
solid metres, and each point reads its ray's counts at its distance. Pure: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from link.radio import RadioParams
from sim.maps.grid import Grid

RAYS_AT_ONCE = 256  # rays marched together: a few million samples, a few megabytes


@dataclass(frozen=True)
class Coverage:
    """The mean link at each point: RSSI (dBm), margin over the receiver's threshold (dB), delivery (0..1)."""

    rssi_dbm: np.ndarray
    margin_db: np.ndarray
    delivery: np.ndarray


def wall_counts(grid: Grid, station: tuple[float, float], north: np.ndarray, east: np.ndarray,
                cell: float) -> tuple[np.ndarray, np.ndarray]:
    """(runs of solid cells crossed, solid metres) on the line of sight from ``station`` (world frame) to each
    point, good to about half a ``cell`` sideways and half a grid cell along."""
    north, east = np.asarray(north, dtype=float), np.asarray(east, dtype=float)
    dn, de = north - station[0], east - station[1]
    dist = np.hypot(dn, de)
    runs = np.zeros(dist.shape, dtype=np.int32)
    metres = np.zeros(dist.shape)
    if dist.size == 0:
        return runs, metres
    far = float(dist.max())
    n_rays = max(8, math.ceil(2 * math.pi * far / (cell / 2)))
    ray = np.rint(np.mod(np.arctan2(de, dn), 2 * math.pi) / (2 * math.pi) * n_rays).astype(np.intp) % n_rays
    step = grid.res / 2
    su, sv = grid.uv(station[0], station[1])
    order = np.argsort(ray, kind="stable")
    bounds = np.searchsorted(ray[order], np.arange(0, n_rays + RAYS_AT_ONCE, RAYS_AT_ONCE))
    for b0, b1 in zip(bounds[:-1], bounds[1:], strict=False):
        if b1 <= b0:
            continue
        idx = order[b0:b1]
        rays = np.unique(ray[idx])
        reach = float(dist[idx].max())
        k = (np.arange(int(reach / step) + 2) + 0.5) * step
        angle = rays * (2 * math.pi / n_rays)
        # a world direction (north, east) turned into the grid's (u, v): east is the map's x
        cn, ce = np.cos(angle)[:, None], np.sin(angle)[:, None]
        du, dv = grid.cos * ce + grid.sin * cn, -grid.sin * ce + grid.cos * cn
        inside = grid.solid_at(su + du * k, sv + dv * k)
        rising = np.zeros(inside.shape, dtype=np.int32)
        rising[:, 0] = inside[:, 0]
        rising[:, 1:] = inside[:, 1:] & ~inside[:, :-1]
        run_at = np.cumsum(rising, axis=1)
        metre_at = np.cumsum(inside, axis=1) * step
        row = np.searchsorted(rays, ray[idx])
        j = np.minimum((dist[idx] / step).astype(np.intp), len(k) - 1)
        # the point's own sample is the last one before it: a point at a wall's face is not inside the wall
        j = np.maximum(j - 1, 0)
        runs[idx] = run_at[row, j]
        metres[idx] = metre_at[row, j]
    return runs, metres


def predict(radio: RadioParams, power_dbm: float, wall_db: float, wall_db_per_m: float,
            station: tuple[float, float], north: np.ndarray, east: np.ndarray, runs: np.ndarray,
            metres: np.ndarray) -> Coverage:
    """The mean channel of ``link.radio.Radio._link`` (shadowing left out) at each point."""
    d = np.maximum(1.0, np.hypot(np.asarray(north) - station[0], np.asarray(east) - station[1]))
    rssi = power_dbm - radio.ref_loss_db - 10.0 * radio.exponent * np.log10(d) - wall_db * runs - wall_db_per_m * metres
    margin = rssi - max(radio.sensitivity_dbm, radio.noise_floor_dbm + 5.0)
    z = np.clip(-margin / max(1e-6, radio.fade_width_db / 4.0), -700.0, 700.0)
    return Coverage(rssi, margin, 1.0 / (1.0 + np.exp(z)))
