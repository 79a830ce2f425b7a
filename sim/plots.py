"""Pictures a person can look at: the world, the paths, the trail and the return route."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from sim.world import World  # noqa: E402


def draw_world(ax, world: World, bounds: tuple[float, float, float, float] | None = None) -> None:
    """Plan view with east to the right and north up (x north, y east in the local frame); a map world's cells
    under it all."""
    world.draw_under(ax)
    for wall in world.walls:
        pts = np.array(wall.points)
        ax.plot(pts[:, 1], pts[:, 0], color="0.25", lw=max(1.0, wall.thickness * 3), solid_capstyle="round",
                zorder=2)
    for poly in world.denied:
        p = np.array(poly + (poly[0],))
        ax.fill(p[:, 1], p[:, 0], color="0.85", alpha=0.6, zorder=0, label="GPS denied")
    for s in world.stations:
        ax.plot(s.y, s.x, marker="^", ms=11, color="tab:purple", zorder=5)
        ax.annotate(f"{s.name} ({s.sysid})", (s.y, s.x), textcoords="offset points", xytext=(6, 6), fontsize=8)
    if bounds:
        ax.set_xlim(bounds[1], bounds[3])
        ax.set_ylim(bounds[0], bounds[2])
    ax.set_aspect("equal")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")


def draw_trail(ax, points: np.ndarray, good: np.ndarray, frame: str = "") -> None:
    """Crumbs by link tag; ``frame`` is appended to the labels (" (estimate frame)") where frames are mixed."""
    ax.plot(points[:, 1], points[:, 0], color="0.6", lw=0.8, zorder=3)
    ax.scatter(points[good, 1], points[good, 0], s=10, color="tab:green", zorder=4,
               label=f"crumb, link good{frame}")
    ax.scatter(points[~good, 1], points[~good, 0], s=10, color="tab:red", zorder=4, label=f"crumb, link lost{frame}")


def draw_route(ax, route: np.ndarray, start: tuple[float, float], radius: float | None) -> None:
    ax.plot(route[:, 1], route[:, 0], color="tab:blue", lw=2.2, zorder=6, label="return route")
    ax.plot(route[-1, 1], route[-1, 0], marker="*", ms=14, color="tab:blue", zorder=7)
    if radius is not None and radius < 5000:
        a = np.linspace(0, 2 * math.pi, 200)
        ax.plot(start[1] + radius * np.sin(a), start[0] + radius * np.cos(a), ls="--", color="tab:blue", lw=0.8,
                label="max displacement")


def save(fig, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def trail_route_figure(world: World, bounds, true_path: np.ndarray, est_path: np.ndarray, points: np.ndarray,
                       good: np.ndarray, route: np.ndarray, radius: float | None, title: str, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(9, 7))
    draw_world(ax, world, bounds)
    ax.plot(true_path[:, 1], true_path[:, 0], color="k", lw=0.7, alpha=0.5, label="true path")
    ax.plot(est_path[:, 1], est_path[:, 0], color="tab:orange", lw=0.7, alpha=0.7, label="estimated path")
    draw_trail(ax, points, good)
    draw_route(ax, route, (route[0, 0], route[0, 1]), radius)
    ax.set_title(title)
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=True))
    ax.legend(uniq.values(), uniq.keys(), loc="best", fontsize=8)
    return save(fig, path)
