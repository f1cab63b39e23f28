"""Occupancy maps exactly as nav2 ``map_server`` loads them: ``<stem>.yaml`` + ``<stem>.pgm``.

Written maps are *trinary*: pixel 0 occupied, 254 free, 205 unknown. A cell is occupied if
its probability ``p > occupied_thresh``, free if ``p < free_thresh``, unknown otherwise
(including NaN). The YAML always carries the standard ``occupied_thresh: 0.65`` and
``free_thresh: 0.196``: map_server reads 0 as p = 1.0, 254 as p = 1/255 and 205 as
p = 50/255 ≈ 0.19608, so those thresholds give back exactly the classes written, whatever
thresholds classified the probabilities.

The loader follows map_server's ``loadMapYaml``/``loadMapFromFile``: the image is relative
to the YAML, RGB channels are averaged (trinary mode also averages in the alpha channel),
``p = 1 − shade`` (``shade`` with ``negate``), then trinary/scale/raw rules. Image row 0 is
the top (max y); arrays here have row 0 at min y.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from formats.arrays import F64
from formats.errors import FormatError
from formats.map_types import DEFAULT_MAX_CELLS, GridSpec
from formats.path_text import path_text_problem, shown
from formats.ranges import CELL_M, COORD_M, Range
from formats.text_file import read_bounded, read_text
from formats.writers.atomic import atomic_write_bytes, atomic_write_text

__all__ = [
    "FREE_PIXEL",
    "OCCUPIED_PIXEL",
    "UNKNOWN_PIXEL",
    "Nav2Map",
    "load_nav2_map",
    "nav2_image_path",
    "trinary_classes",
    "write_nav2_map",
]

OCCUPIED_PIXEL = 0
FREE_PIXEL = 254
UNKNOWN_PIXEL = 205
OCCUPIED, FREE, UNKNOWN = 1, 0, -1  # classes of trinary_classes
YAML_OCCUPIED_THRESH = 0.65
YAML_FREE_THRESH = 0.196
MAX_YAML_BYTES = 1 << 20  # a map YAML is a few lines
_IMAGE_HEADER_BYTES = 1 << 20  # an image file's bytes beyond its pixels (headers, comments)
_MAX_BYTES_PER_CELL = 8  # the most any accepted image spends on a pixel (P2: "65535 ")



@dataclass(frozen=True)
class Nav2Map:
    """A map as map_server would publish it; all arrays H×W with row 0 at min y.

    ``classes``: int8, 1 occupied (p > occupied_thresh), 0 free (p < free_thresh), −1
    otherwise (unknown, or between the thresholds in scale/raw mode).
    ``probability``: float32 occupancy probability p, NaN where map_server publishes −1.
    ``occupancy``: int8 OccupancyGrid values as map_server publishes them (0..100, −1).
    ``yaml``: the parsed YAML document.
    """

    classes: npt.NDArray[np.int8]
    probability: npt.NDArray[np.float32]
    grid: GridSpec
    yaml: dict[str, Any]
    occupancy: npt.NDArray[np.int8]


# -- writing ---------------------------------------------------------------------------


def _yaml_string(text: str) -> str:
    # JSON strings are valid YAML double-quoted scalars; plain style only when unambiguous.
    return text if re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.\-]*", text) else json.dumps(text)


def _number(value: float, what: str) -> str:
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{what} must be finite, got {v!r}")
    return repr(v)


def trinary_classes(
    probability: np.ndarray, *, occupied_thresh: float = 0.65, free_thresh: float = 0.196
) -> npt.NDArray[np.int8]:
    """The one classification of a probability map (every output uses it): int8, 1 where
    ``p > occupied_thresh``, 0 where ``p < free_thresh``, −1 otherwise (NaN included)."""
    prob = np.asarray(probability)
    classes = np.full(prob.shape, UNKNOWN, dtype=np.int8)
    with np.errstate(invalid="ignore"):  # NaN compares False: stays unknown
        classes[prob > occupied_thresh] = OCCUPIED
        classes[prob < free_thresh] = FREE
    return classes


def write_nav2_map(
    yaml_path: Path,
    probability: np.ndarray,
    grid: GridSpec,
    *,
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
) -> None:
    """Write ``<stem>.pgm`` (binary P5, trinary) and the map_server YAML at ``yaml_path``.

    ``probability``: float32 H×W, row 0 at min y, NaN unknown. Cells with
    ``p > occupied_thresh`` become 0 (occupied), ``p < free_thresh`` 254 (free), the rest
    205 (unknown). ``origin`` is the lower-left corner of the grid (m), yaw 0. Both files
    are written atomically; the bytes depend only on the inputs.
    """
    yaml_path = Path(yaml_path)
    prob = np.asarray(probability)
    if prob.shape != grid.shape:
        raise ValueError(f"probability has shape {prob.shape}, grid is {grid.shape}")
    if not 0.0 <= free_thresh < occupied_thresh <= 1.0:
        raise ValueError(
            f"need 0 <= free_thresh < occupied_thresh <= 1, got {free_thresh}, {occupied_thresh}"
        )
    if not (grid.resolution > 0 and math.isfinite(grid.resolution)):
        raise ValueError(f"resolution must be a positive finite number, got {grid.resolution}")

    classes = trinary_classes(prob, occupied_thresh=occupied_thresh, free_thresh=free_thresh)
    pixels = np.full(prob.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    pixels[classes == OCCUPIED] = OCCUPIED_PIXEL
    pixels[classes == FREE] = FREE_PIXEL
    # Image row 0 is the top of the map (max y); the grid's row 0 is min y.
    body = np.ascontiguousarray(pixels[::-1]).tobytes()
    header = f"P5\n{grid.width} {grid.height}\n255\n".encode("ascii")

    image_name = yaml_path.stem + ".pgm"
    text = (
        f"image: {_yaml_string(image_name)}\n"
        "mode: trinary\n"
        f"resolution: {_number(grid.resolution, 'resolution')}\n"
        f"origin: [{_number(grid.origin_x, 'origin_x')}, "
        f"{_number(grid.origin_y, 'origin_y')}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {YAML_OCCUPIED_THRESH!r}\n"
        f"free_thresh: {YAML_FREE_THRESH!r}\n"
    )
    # Image first: a YAML never points at a missing image.
    atomic_write_bytes(yaml_path.with_name(image_name), header + body)
    atomic_write_text(yaml_path, text)


# -- reading ---------------------------------------------------------------------------

_PNM_TOKEN = re.compile(rb"\s*(?:#[^\n]*\n\s*)*(\S+)")


def _read_pgm(path: Path, data: bytes, max_cells: int) -> F64:
    """Grey levels in [0, 1] of a P5 (binary) or P2 (ASCII) PGM, image row 0 first; the
    size its header declares is checked against ``max_cells`` before anything is built."""
    magic = data[:2]
    pos = 2
    header: list[int] = []
    for _ in range(3):
        m = _PNM_TOKEN.match(data, pos)
        if m is None or not m.group(1).isdigit():
            raise FormatError("PGM header is truncated or not numeric", path)
        header.append(int(m.group(1)))
        pos = m.end()
    width, height, maxval = header
    if width <= 0 or height <= 0 or not 0 < maxval < 65536:
        raise FormatError(f"bad PGM header: {width}x{height}, maxval {maxval}", path)
    n = width * height
    _check_cells(path, width, height, max_cells)
    if magic == b"P5":
        pos += 1  # exactly one whitespace byte separates the header from the raster
        dtype = np.dtype(np.uint8) if maxval < 256 else np.dtype(">u2")
        need = n * dtype.itemsize
        if len(data) - pos < need:
            raise FormatError(
                f"PGM raster truncated: {len(data) - pos} bytes, expected {need}", path
            )
        values = np.frombuffer(data, dtype=dtype, count=n, offset=pos).astype(np.float64)
    else:
        try:
            values = np.array(data[pos:].split()[:n], dtype=np.float64)
        except ValueError as err:
            raise FormatError("P2 raster has a non-numeric value", path) from err
        if values.size < n:
            raise FormatError(f"P2 raster truncated: {values.size} values, expected {n}", path)
    if np.any(values > maxval):
        raise FormatError(f"PGM value above maxval {maxval}", path)
    return (values / maxval).reshape(height, width)


def _check_cells(path: Path, width: int, height: int, max_cells: int) -> None:
    if width * height > max_cells:
        raise FormatError(f"map image declares {width}x{height} pixels, more than "
                          f"grid.max_cells = {max_cells}", path)


def _read_image(path: Path, max_cells: int) -> tuple[F64, F64 | None]:
    """``(shade, alpha)`` in [0, 1] per pixel, image row 0 first; alpha None when opaque.

    ``shade`` is the mean of the colour channels, as map_server computes it. The file is
    read only when it is a regular file of a size ``max_cells`` pixels can have, and the
    pixel count its header declares is checked before the pixels are decoded.
    """
    cap = _IMAGE_HEADER_BYTES + _MAX_BYTES_PER_CELL * max_cells
    data = read_bounded(path, "map image", cap, errors=(FormatError, FormatError))
    if data[:2] in (b"P5", b"P2"):
        return _read_pgm(path, data, max_cells), None

    import io

    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as img:
            _check_cells(path, img.width, img.height, max_cells)
            img.load()
            mode = img.mode
            if mode in ("I;16", "I;16B", "I;16L", "I"):
                grey = np.asarray(img, dtype=np.float64)
                return np.clip(grey / 65535.0, 0.0, 1.0), None
            has_alpha = mode in ("RGBA", "LA", "PA", "La", "RGBa") or "transparency" in img.info
            rgba = np.asarray(img.convert("RGBA" if has_alpha else "RGB"), dtype=np.float64)
    except (UnidentifiedImageError, OSError, ValueError) as err:
        raise FormatError(f"not a readable image ({err})", path) from err
    shade = rgba[..., :3].mean(axis=-1) / 255.0
    alpha = rgba[..., 3] / 255.0 if has_alpha else None
    return shade, alpha


# A number YAML 1.1 reads as a string (``5e-2``: no dot, no sign in the exponent) is
# still the number map_server (yaml-cpp) reads.
_FLOAT_TEXT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def _get_number(doc: dict[str, Any], key: str, path: Path) -> float:
    if key not in doc:
        raise FormatError(f"map YAML has no '{key}'", path)
    value = doc[key]
    if isinstance(value, str) and _FLOAT_TEXT.fullmatch(value.strip()):
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise FormatError(f"map YAML '{key}' is not a number: {value!r}", path)
    return float(value)


THRESHOLD = Range(-1e6, 1e6)


def _check_range(value: float, rng: Range, key: str, path: Path) -> None:
    if not rng.holds(value):
        raise FormatError(f"map YAML '{key}' {rng.rule()}, got {value!r}", path)


def _read_yaml(yaml_path: Path) -> dict[str, Any]:
    text = read_text(yaml_path, "map YAML", errors=(FormatError, FormatError),
                     max_bytes=MAX_YAML_BYTES)
    try:
        doc = yaml.safe_load(text)
    except (yaml.YAMLError, RecursionError) as err:
        reason = " ".join(str(err).split())
        raise FormatError(f"not a readable map YAML: {reason}", yaml_path) from err
    if not isinstance(doc, dict):
        raise FormatError("map YAML is not a mapping", yaml_path)
    return doc


def _image_path(yaml_path: Path, doc: dict[str, Any]) -> Path:
    image = doc.get("image")
    if not isinstance(image, str) or not image:
        raise FormatError("map YAML has no 'image' (or it is empty)", yaml_path)
    problem = path_text_problem(image)
    if problem is not None:
        raise FormatError(f"map YAML 'image' {shown(image)} {problem}", yaml_path)
    return Path(image) if Path(image).is_absolute() else yaml_path.parent / image


def nav2_image_path(yaml_path: Path) -> Path | None:
    """The image a nav2 map YAML names, or None when the YAML cannot be read."""
    try:
        return _image_path(Path(yaml_path), _read_yaml(Path(yaml_path)))
    except FormatError:
        return None


def load_nav2_map(yaml_path: Path, max_cells: int = DEFAULT_MAX_CELLS) -> Nav2Map:
    """Load a nav2 map (YAML + image) with map_server's rules; see the module docstring.
    An image of more than ``max_cells`` pixels is refused before it is decoded."""
    yaml_path = Path(yaml_path)
    doc = _read_yaml(yaml_path)
    image_path = _image_path(yaml_path, doc)
    resolution = _get_number(doc, "resolution", yaml_path)
    _check_range(resolution, CELL_M, "resolution", yaml_path)
    origin = doc.get("origin")
    if not isinstance(origin, list) or len(origin) != 3:
        raise FormatError(
            f"map YAML 'origin' must be a list of 3 numbers, got {origin!r}", yaml_path
        )
    try:
        ox, oy, yaw = (float(v) for v in origin)
    except (TypeError, ValueError) as err:
        raise FormatError(f"map YAML 'origin' has a non-number: {origin!r}", yaml_path) from err
    _check_range(ox, COORD_M, "origin[0]", yaml_path)
    _check_range(oy, COORD_M, "origin[1]", yaml_path)
    if yaw != 0.0:
        raise FormatError(f"map origin yaw {yaw} rad is not supported (only 0)", yaml_path)
    occ_th = _get_number(doc, "occupied_thresh", yaml_path)
    free_th = _get_number(doc, "free_thresh", yaml_path)
    # Thresholds beyond [0, 1] are allowed (map_server's "nothing occupied"), not NaN.
    _check_range(occ_th, THRESHOLD, "occupied_thresh", yaml_path)
    _check_range(free_th, THRESHOLD, "free_thresh", yaml_path)
    if not free_th < occ_th:
        raise FormatError(f"map YAML 'free_thresh' must be < occupied_thresh, got {free_th}"
                          f" and {occ_th}", yaml_path)
    mode = doc.get("mode", "trinary")
    if mode not in ("trinary", "scale", "raw"):
        raise FormatError(f"map YAML 'mode' must be trinary, scale or raw, got {mode!r}", yaml_path)
    if "negate" not in doc or not isinstance(doc["negate"], int | bool):
        raise FormatError("map YAML 'negate' must be 0 or 1 (or a boolean)", yaml_path)
    negate = bool(doc["negate"])

    shade, alpha = _read_image(image_path, max_cells)
    if mode == "trinary" and alpha is not None:
        # map_server averages opacity in with the colour channels in trinary mode.
        shade = (3.0 * shade + alpha) / 4.0
    occ = shade if negate else 1.0 - shade

    occupancy = np.full(occ.shape, -1, dtype=np.int8)
    if mode == "raw":
        value = np.round(shade * 255.0)
        ok = (value >= 0) & (value <= 100)
        occupancy[ok] = value[ok].astype(np.int8)
        prob = np.where(ok, value / 100.0, np.nan)
    else:
        is_occ = occ > occ_th
        is_free = occ < free_th
        occupancy[is_occ] = 100
        occupancy[is_free] = 0
        if mode == "trinary":
            prob = np.where(is_occ | is_free, occ, np.nan)
        else:  # scale: transparent pixels are unknown, the rest scaled between thresholds
            between = ~(is_occ | is_free)
            opaque = np.ones(occ.shape, dtype=bool) if alpha is None else alpha >= 1.0
            scaled = np.rint((occ - free_th) / (occ_th - free_th) * 100.0)
            occupancy[between] = scaled[between].astype(np.int8)
            occupancy[~opaque] = -1
            prob = np.where(opaque, occ, np.nan)

    with np.errstate(invalid="ignore"):
        classes = np.where(prob > occ_th, 1, np.where(prob < free_th, 0, -1)).astype(np.int8)
    height, width = occ.shape
    return Nav2Map(
        classes=np.ascontiguousarray(classes[::-1]),
        probability=np.ascontiguousarray(prob[::-1].astype(np.float32)),
        grid=GridSpec(ox, oy, resolution, int(width), int(height)),
        yaml=doc,
        occupancy=np.ascontiguousarray(occupancy[::-1]),
    )
