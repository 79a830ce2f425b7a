"""Small map_server maps drawn for the tests: a YAML file and a PGM written into a directory, as map_saver would.

``building`` is a corridor with rooms off it behind walls, the station outside its open end: the link dies in the
far rooms, so routes, surveys and runs have something to find. Cells are 254 (free), 0 (occupied), 205 (unknown),
map_saver's own values.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

FREE, OCCUPIED, UNKNOWN = 254, 0, 205


def write_pgm(path: Path, cells: np.ndarray, binary: bool = True) -> Path:
    """``cells`` (rows top first, uint8 or uint16) as a P5 (or P2) PGM."""
    h, w = cells.shape
    top = 65535 if cells.dtype == np.uint16 else 255
    if binary:
        body = cells.astype(">u2" if top > 255 else np.uint8).tobytes()
        path.write_bytes(f"P5\n{w} {h}\n{top}\n".encode() + body)
    else:
        rows = "\n".join(" ".join(str(int(v)) for v in row) for row in cells)
        path.write_text(f"P2\n{w} {h}\n{top}\n{rows}\n")
    return path


def write_yaml(path: Path, image: str, resolution: float, origin=(0.0, 0.0, 0.0), extra: str = "") -> Path:
    path.write_text(f"image: {image}\nresolution: {resolution}\norigin: [{origin[0]}, {origin[1]}, {origin[2]}]\n"
                    f"negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n{extra}")
    return path


def building_cells(res: float = 0.1, rooms: int = 4) -> np.ndarray:
    """A 48 m x 24 m building (rows top first): a 3 m corridor along x from the open west end, ``rooms`` rooms
    north and south of it behind 0.2 m walls with 2.4 m doors, unknown outside."""
    w, h = round(48 / res), round(24 / res)
    cells = np.full((h, w), UNKNOWN, dtype=np.uint8)
    t = max(1, round(0.2 / res))

    def box(x0, y0, x1, y1, v):  # metres, y up: rows count down from the top
        cells[h - round(y1 / res):h - round(y0 / res), round(x0 / res):round(x1 / res)] = v

    box(0, 2, 46, 22, OCCUPIED)
    box(0.0, 2 + 0.2, 46 - 0.2, 22 - 0.2, FREE)
    box(0.0, 10.5 - 0.2, 46, 10.5, OCCUPIED)   # corridor walls at y = 10.5 and 13.5
    box(0.0, 13.5, 46, 13.5 + 0.2, OCCUPIED)
    span = 36.0 / rooms
    for k in range(rooms + 1):
        x = 10 + k * span
        box(x, 2, x + 0.2, 10.5, OCCUPIED)
        box(x, 13.5, x + 0.2, 22, OCCUPIED)
    for k in range(rooms):
        x = 10 + k * span + span / 2
        box(x, 10.5 - 0.2, x + 2.4, 10.5, FREE)
        box(x, 13.5, x + 2.4, 13.5 + 0.2, FREE)
    box(0, 10.5, 10, 13.5, FREE)
    del t
    return cells


def building(directory: Path, res: float = 0.1, rooms: int = 4) -> Path:
    """The building map's YAML in ``directory``; the station stands at (1.5, 12.0), in the corridor's mouth."""
    directory.mkdir(parents=True, exist_ok=True)
    write_pgm(directory / "building.pgm", building_cells(res, rooms))
    return write_yaml(directory / "building.yaml", "building.pgm", res)


STATION = (1.5, 12.0)
