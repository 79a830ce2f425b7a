"""`returnlink site survey`: where the link reaches on an owner's map, and where it dies.

The predicted coverage is the mean channel (``sim.maps.coverage``: no shadowing, the same for every seed) at every
open place of the map, on blocks of about ``SURVEY_CELL``: ``coverage.csv`` (map frame: x east, y north, metres)
and ``coverage.png`` (the delivery over the map, the frontier where it falls through 50 %, the places a robot can
drive to). The campaign of returns to goals beyond coverage is an ordinary sweep (``sim.campaign``) over a scenario
file that names the map, written beside the survey, so every trial replays with `sim run --replay`.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from link.radio import RadioParams
from link.storage import write_atomic
from sim.maps import coverage
from sim.maps.grid import Grid, Site
from sim.world import Station

SURVEY_CELL = 0.25  # m: the survey's blocks (a map finer than this is surveyed on blocks of its cells)
FRONTIER = 0.5  # delivery: the frontier is where the predicted delivery falls through this


@dataclass(frozen=True)
class Survey:
    """The mean link at every open survey block: map-frame x (east) and y (north), RSSI, delivery."""

    x: np.ndarray
    y: np.ndarray
    rssi_dbm: np.ndarray
    delivery: np.ndarray
    cell: float
    frontier: np.ndarray  # bool per block: alive (>= FRONTIER) with a dead neighbour block

    @property
    def covered(self) -> float:
        """Share of the open blocks where delivery is at least FRONTIER."""
        return float(np.mean(self.delivery >= FRONTIER)) if len(self.delivery) else 0.0


def survey(grid: Grid, site: Site, station: Station, radio: RadioParams) -> Survey:
    """The predicted coverage of ``grid``'s open places from ``station`` (world frame)."""
    f = max(1, round(SURVEY_CELL / grid.res))
    rows, cols = np.arange(f // 2, grid.rows, f), np.arange(f // 2, grid.cols, f)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    open_ = ~grid.solid[rr, cc]
    north, east = grid.cell_centre(rr[open_], cc[open_])
    runs, metres = coverage.wall_counts(grid, (station.x, station.y), north, east, f * grid.res)
    cov = coverage.predict(radio, station.power_dbm, site.wall_db, site.wall_db_per_m, (station.x, station.y),
                           north, east, runs, metres)
    alive = np.zeros(rr.shape, dtype=bool)
    dead = np.zeros(rr.shape, dtype=bool)
    alive[open_] = cov.delivery >= FRONTIER
    dead[open_] = cov.delivery < FRONTIER
    near_dead = np.zeros_like(dead)
    near_dead[1:, :] |= dead[:-1, :]
    near_dead[:-1, :] |= dead[1:, :]
    near_dead[:, 1:] |= dead[:, :-1]
    near_dead[:, :-1] |= dead[:, 1:]
    frontier = (alive & near_dead)[open_]
    return Survey(east, north, cov.rssi_dbm, cov.delivery, f * grid.res, frontier)


def write_csv(s: Survey, path: Path) -> Path:
    """``coverage.csv``: x, y (map frame, m), rssi_dbm, delivery, one row per open survey block."""
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(("x", "y", "rssi_dbm", "delivery"))
    for row in zip(np.round(s.x, 3).tolist(), np.round(s.y, 3).tolist(), np.round(s.rssi_dbm, 1).tolist(),
                   np.round(s.delivery, 4).tolist(), strict=True):
        w.writerow(row)
    write_atomic(path, buf.getvalue().encode("utf-8"))
    return path


def draw(s: Survey, grid: Grid, station: Station, path: Path, title: str, reach: np.ndarray | None = None) -> Path:
    """``coverage.png``: the map, the predicted delivery over its open places, the frontier and the station."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.plots import save

    w, h = grid.cols * grid.res, grid.rows * grid.res
    fig, ax = plt.subplots(figsize=(max(6.0, min(14.0, 9.0 * w / max(w, h) + 3)), max(5.0, min(12.0, 9.0 * h /
                                                                                                 max(w, h)))))
    grid.draw(ax)
    size = max(0.5, (72.0 * s.cell * 8.0 / max(w, h)) ** 2)
    pts = ax.scatter(s.x, s.y, c=s.delivery, s=size, marker="s", cmap="RdYlGn", vmin=0.0, vmax=1.0, linewidths=0,
                     zorder=1)
    fig.colorbar(pts, ax=ax, shrink=0.7, label="predicted packet delivery (mean link)")
    ax.scatter(s.x[s.frontier], s.y[s.frontier], s=size, marker="s", color="black", linewidths=0, zorder=2,
               label=f"frontier (delivery falls through {FRONTIER:g})")
    ax.plot(station.y, station.x, marker="^", ms=12, color="tab:purple", ls="none", zorder=5, label="station")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, map frame: east)")
    ax.set_ylabel("y (m, map frame: north)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="best", fontsize=7)
    return save(fig, path)


def site_scenario(yaml: Path, station_xy: tuple[float, float], radio: dict[str, float], name: str) -> str:
    """The scenario file of a survey's campaign: the map (absolute path), the station, the radio; no [operator],
    so each seed draws its own goal beyond coverage."""
    import json

    lines = [f"name = {json.dumps(name)}", "", "[map]", f"file = {json.dumps(str(yaml.resolve()))}",
             f"station = [{float(station_xy[0])!r}, {float(station_xy[1])!r}]"]
    if radio:
        lines += ["", "[radio]"] + [f"{k} = {float(v)!r}" for k, v in radio.items()]
    return "\n".join(lines) + "\n"


def campaign_spec(trials: int, policies: list[str], vehicles: list[str]) -> str:
    """The sweep spec of a survey's campaign: ``site.toml`` beside it, seeds 1..trials, both robots."""
    import json

    return (f"# written by returnlink site survey\nscenarios = [\"site.toml\"]\nvehicles = {json.dumps(vehicles)}\n"
            f"seeds = {{ from = 1, to = {int(trials)} }}\npolicies = {json.dumps(policies)}\ntimeout_s = 600\n")


def summary_lines(s: Survey) -> list[str]:
    """What the survey found, for a person."""
    area = len(s.x) * s.cell * s.cell
    share = (lambda m: 100.0 * float(np.mean(m)) if len(s.x) else 0.0)  # noqa: E731 - a local percentage
    return [f"  {area:,.0f} m2 of open map surveyed on {s.cell:g} m blocks ({len(s.x):,} places)",
            f"  predicted delivery >= {FRONTIER:g} over {share(s.delivery >= FRONTIER):.1f} % of it, >= 0.9 over "
            f"{share(s.delivery >= 0.9):.1f} %",
            f"  frontier: {int(s.frontier.sum()):,} blocks (about {s.frontier.sum() * s.cell:,.0f} m of edge) where "
            "the predicted link dies"]
