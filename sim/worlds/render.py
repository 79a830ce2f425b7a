"""``world.png``: a scenario's map before anything runs, so a person can see what a generated world is.

Walls coloured by their radio attenuation (a colour bar in dB), GPS-denied zones shaded, the stations, the start,
the operator's route as it is driven (``check.steered_path``) with its waypoints, and where the mean link is last
alive and first dies along it. Headless (matplotlib's Agg), like ``sim/plots.py``.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import cm, colors  # noqa: E402

from sim.plots import save  # noqa: E402
from sim.scenario import Scenario  # noqa: E402
from sim.worlds.check import Verdict, steered_path  # noqa: E402


def render(sc: Scenario, path: Path, verdict: Verdict | None = None) -> Path:
    """Draw ``sc`` (east to the right, north up, as ``sim/plots.py``) to ``path``."""
    fig, ax = plt.subplots(figsize=(9, 7))
    if sc.site is not None:  # a map world: its cells
        sc.site.grid().draw(ax)
    top = max([w.attenuation_db for w in sc.walls] or [1.0])
    norm = colors.Normalize(0.0, max(top, 1.0))
    cmap = plt.get_cmap("plasma_r")
    for poly in sc.denied:
        p = np.array(poly + (poly[0],))
        ax.fill(p[:, 1], p[:, 0], color="0.82", alpha=0.6, zorder=0, label="GPS denied")
    for wall in sc.walls:
        pts = np.array(wall.points)
        ax.plot(pts[:, 1], pts[:, 0], color=cmap(norm(wall.attenuation_db)), lw=max(1.5, wall.thickness * 4),
                solid_capstyle="round", zorder=2)
    if sc.site is None:
        fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.7, label="wall attenuation (dB)")
    for s in sc.stations:
        ax.plot(s.y, s.x, marker="^", ms=11, color="tab:purple", zorder=5, ls="none", label="station")
        ax.annotate(f"{s.name} ({s.power_dbm:g} dBm)", (s.y, s.x), textcoords="offset points", xytext=(6, 6),
                    fontsize=8)
    driven = np.array(steered_path(sc.start[:2], sc.route))
    ax.plot(driven[:, 1], driven[:, 0], color="tab:blue", lw=1.8, zorder=4, label="operator's route (driven)")
    way = np.array([p[:2] for p in sc.route])
    ax.plot(way[:, 1], way[:, 0], ls="none", marker=".", color="tab:blue", alpha=0.5, zorder=4, label="waypoints")
    ax.plot(sc.start[1], sc.start[0], marker="o", ms=8, color="tab:green", zorder=6, ls="none", label="start")
    if verdict is not None and verdict.alive_at is not None:
        ax.plot(verdict.alive_at[1], verdict.alive_at[0], marker="P", ms=10, color="tab:green", zorder=6,
                ls="none", label="link last alive (mean)")
    if verdict is not None and verdict.dead_at is not None:
        ax.plot(verdict.dead_at[1], verdict.dead_at[0], marker="X", ms=10, color="tab:red", zorder=6, ls="none",
                label="link dies (mean)")
    b = sc.bounds
    ax.set_xlim(b[1], b[3])
    ax.set_ylim(b[0], b[2])
    ax.set_aspect("equal")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    loss = (f"; walls {sc.site.wall_db:g} dB a crossing + {sc.site.wall_db_per_m:g} dB/m" if sc.site is not None
            else "")
    ax.set_title(f"{sc.name} (seed {sc.seed}{loss})")
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    ax.legend(unique.values(), unique.keys(), loc="best", fontsize=7)
    return save(fig, path)
