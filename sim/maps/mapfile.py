"""A ROS map_server map read exactly as ROS reads it: the YAML's fields and the image's cells.

The YAML (``image``, ``resolution``, ``origin`` [x, y, yaw], ``negate``, ``occupied_thresh``, ``free_thresh``,
``mode``) is what gmapping, Cartographer, slam_toolbox and Nav2's map_saver write. Each pixel becomes a cell as in
map_server's image loader: the channels are averaged (colour images), 16-bit images are scaled to 8 bits, ``negate``
flips the shade, and the occupancy is ``p = (255 - shade) / 255``:

- ``trinary`` (default): occupied if ``p > occupied_thresh``, free if ``p < free_thresh``, unknown otherwise;
- ``scale``: the same, and a pixel that is not opaque is unknown (values between the thresholds are a probability
  in the OccupancyGrid; a world needs solid or not, so they count as unknown here too);
- ``raw``: the shade itself is the OccupancyGrid value: 0..100 is a percentage (occupied above
  ``occupied_thresh`` x 100, free below ``free_thresh`` x 100, unknown between), anything above 100 unknown.

Row 0 of the image is the map's top edge; ``origin`` is the pose of the lower-left cell's corner in the map frame
(metres, REP 103: x east, y north, yaw counter-clockwise). Every problem is a MapError naming the file, the line and
the field, because a map's YAML is written by a tool and then edited by hand.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MODES = ("trinary", "scale", "raw")
# map_server's own defaults where a file leaves a threshold out (the values map_saver writes)
DEFAULT_OCCUPIED, DEFAULT_FREE = 0.65, 0.196
MAX_CELLS = 50_000_000  # a map larger than this is refused before its arrays are made (3 bytes a cell)


class MapError(ValueError):
    """A map that cannot be read; the message names the file, the line (when known) and the field."""

    def __init__(self, file: str, line: int | None, fld: str, message: str) -> None:
        self.file, self.line, self.field = file, line, fld
        where = f"{file}:{line}" if line else file
        super().__init__(f"{where}: {fld}: {message}" if fld else f"{where}: {message}")


@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """The cells of one map, in the map's own grid: ``occupied``/``free``/``unknown`` are boolean arrays indexed
    ``[row, column]`` with row 0 at the *bottom* (south edge when yaw is 0), so a cell's row grows with the map's y.
    ``digest`` names the content (YAML and image bytes), so a written world can tell when its map changed."""

    yaml_file: str
    image_file: str
    resolution: float  # m per cell
    origin: tuple[float, float, float]  # the lower-left corner's pose: x, y (m), yaw (rad)
    occupied: np.ndarray
    free: np.ndarray
    unknown: np.ndarray
    digest: str

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape  # type: ignore[return-value]

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) in metres: columns and rows times the resolution."""
        return self.shape[1] * self.resolution, self.shape[0] * self.resolution

    def to_cell(self, x: float, y: float) -> tuple[int, int]:
        """The (row, column) holding map-frame point (x, y) (may lie off the map: check ``on_map``)."""
        ox, oy, yaw = self.origin
        dx, dy = x - ox, y - oy
        c, s = math.cos(yaw), math.sin(yaw)
        u, v = c * dx + s * dy, -s * dx + c * dy
        return math.floor(v / self.resolution), math.floor(u / self.resolution)

    def on_map(self, row: int, col: int) -> bool:
        return 0 <= row < self.shape[0] and 0 <= col < self.shape[1]


class _Yaml:
    """The YAML's mapping with the line each key was written on (for errors)."""

    def __init__(self, file: str, text: str) -> None:
        import yaml

        self.file = file
        try:
            node = yaml.compose(text, Loader=yaml.SafeLoader)
            data = yaml.safe_load(text)
        except yaml.YAMLError as e:
            mark = getattr(e, "problem_mark", None)
            raise MapError(file, mark.line + 1 if mark else None, "", f"not valid YAML: {e}") from None
        if not isinstance(data, dict) or node is None or not hasattr(node, "value"):
            raise MapError(file, None, "", "must be a YAML mapping of map_server's fields (image, resolution, ...)")
        self.data = data
        self.lines = {k.value: k.start_mark.line + 1 for k, _ in node.value if hasattr(k, "value")}

    def fail(self, key: str, message: str) -> MapError:
        return MapError(self.file, self.lines.get(key), key, message)

    def number(self, key: str, default: float | None = None, lo: float = -math.inf, hi: float = math.inf,
               open_lo: bool = False) -> float:
        if key not in self.data:
            if default is None:
                raise MapError(self.file, None, key, "is missing (map_server needs it)")
            return default
        v = self.data[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.fail(key, f"must be a finite number, got {v!r}")
        if v < lo or v > hi or (open_lo and v <= lo):
            raise self.fail(key, f"must be within {'(' if open_lo else '['}{lo:g}, {hi:g}], got {v!r}")
        return float(v)


def _gray(path: Path, file: str, line: int | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The image as map_server sees it: the channels' mean on 0..255 (float) and the alpha channel (0..1) if
    any. Pillow reads PGM (P2/P5, 8 and 16 bit) and PNG."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            w, h = im.size
            if w * h > MAX_CELLS:
                raise MapError(file, line, "image", f"{path.name} has {w} x {h} cells, more than {MAX_CELLS:,}")
            im.load()
            mode = im.mode
            if mode == "P":
                im = im.convert("RGBA")
                mode = im.mode
            a = np.asarray(im)
    except MapError:
        raise
    except (OSError, UnidentifiedImageError, ValueError) as e:
        raise MapError(file, line, "image", f"cannot read {path}: {e}") from None
    alpha = None
    if mode in ("I;16", "I;16B", "I;16L", "I;16N", "I"):
        # 16 bits: map_server scales a quantum to the same 0..1 shade an 8-bit pixel gives
        top = 65535.0 if a.max(initial=0) > 255 or mode.startswith("I;16") else 255.0
        gray = a.astype(np.float64) * (255.0 / top)
    elif a.ndim == 2:
        gray = a.astype(np.float64) * (255.0 if mode == "1" else 1.0)
    else:
        channels = a.shape[2]
        if mode in ("LA", "RGBA") or channels in (2, 4):
            alpha = a[:, :, -1].astype(np.float64) / 255.0
            gray = a[:, :, :-1].astype(np.float64).mean(axis=2)
        else:
            gray = a.astype(np.float64).mean(axis=2)
    return gray, alpha


def classify(gray: np.ndarray, alpha: np.ndarray | None, negate: bool, occupied_thresh: float, free_thresh: float,
             mode: str) -> tuple[np.ndarray, np.ndarray]:
    """(occupied, free) masks of map_server's loader for the image's shades (0..255) in image order; unknown is
    neither. Pure, so the rules are tested on small arrays."""
    shade = 255.0 - gray if negate else gray
    if mode == "raw":
        value = np.rint(shade)
        occupied = (value <= 100) & (value > occupied_thresh * 100.0)
        free = (value <= 100) & (value < free_thresh * 100.0)
        return occupied, free
    p = (255.0 - shade) / 255.0
    occupied = p > occupied_thresh
    free = (p < free_thresh) & ~occupied
    if mode == "scale" and alpha is not None:
        opaque = alpha >= 1.0
        occupied &= opaque
        free &= opaque
    return occupied, free


def read(path: str | Path) -> OccupancyMap:
    """The map of a map_server YAML file; MapError naming the file, line and field for anything wrong. Cached
    by path, size and modification time: a campaign's trials on one map read it once per process."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as e:
        raise MapError(str(p), None, "", f"cannot read the map file: {e.strerror or e}") from None
    return _read(str(p.resolve()), st.st_size, st.st_mtime_ns, str(p))


@functools.lru_cache(maxsize=4)
def _read(resolved: str, size: int, mtime_ns: int, shown: str) -> OccupancyMap:
    p = Path(resolved)
    try:
        raw = p.read_bytes()
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise MapError(shown, None, "", f"cannot read the map file: {getattr(e, 'strerror', None) or e}") from None
    y = _Yaml(shown, text)
    if "image" not in y.data:
        raise MapError(shown, None, "image", "is missing (map_server needs the image's file name)")
    image = y.data["image"]
    if not isinstance(image, str) or not image.strip():
        raise y.fail("image", f"must be the image's file name, got {image!r}")
    resolution = y.number("resolution", None, 0.0, 100.0, open_lo=True)
    origin = y.data.get("origin", [0.0, 0.0, 0.0])
    if (not isinstance(origin, list) or len(origin) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in origin)):
        raise y.fail("origin", f"must be [x, y, yaw] (metres, metres, radians), got {origin!r}")
    negate = y.data.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise y.fail("negate", f"must be 0 or 1, got {negate!r}")
    occ = y.number("occupied_thresh", DEFAULT_OCCUPIED, 0.0, 1.0)
    free = y.number("free_thresh", DEFAULT_FREE, 0.0, 1.0)
    if free > occ:
        raise y.fail("free_thresh", f"must not exceed occupied_thresh ({occ:g}), got {free:g}")
    mode = y.data.get("mode", "trinary")
    if mode not in MODES:
        raise y.fail("mode", f"must be one of {', '.join(MODES)}, got {mode!r}")
    img = Path(image) if Path(image).is_absolute() else p.parent / image
    if not img.is_file():
        raise y.fail("image", f"no such image file: {img}")
    gray, alpha = _gray(img, shown, y.lines.get("image"))
    occupied, freemask = classify(gray, alpha, bool(negate), occ, free, mode)
    h = hashlib.sha256(raw)
    h.update(img.read_bytes())
    # image row 0 is the top edge: flip so a row index grows with the map's y
    occupied, freemask = np.ascontiguousarray(occupied[::-1]), np.ascontiguousarray(freemask[::-1])
    return OccupancyMap(shown, str(img), float(resolution), (float(origin[0]), float(origin[1]), float(origin[2])),
                        occupied, freemask, ~(occupied | freemask), h.hexdigest()[:16])
