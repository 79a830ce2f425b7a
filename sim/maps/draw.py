"""A map's cells drawn under a plan view (east right, north up: the map frame itself, so no axes swap)."""

from __future__ import annotations

import numpy as np
from matplotlib import transforms

from sim.maps.grid import Grid


def draw_grid(ax, grid: Grid, zorder: float = 0) -> None:
    """Solid cells dark, open ones white, turned by the map origin's yaw about the origin."""
    shade = np.where(grid.solid, 0.35, 1.0)
    extent = (grid.ox, grid.ox + grid.cols * grid.res, grid.oy, grid.oy + grid.rows * grid.res)
    im = ax.imshow(shade, origin="lower", extent=extent, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest",
                   zorder=zorder)
    if grid.yaw:
        im.set_transform(transforms.Affine2D().rotate_around(grid.ox, grid.oy, grid.yaw) + ax.transData)
