"""``map.png``: the map as a person reads it.

Occupancy in grey (free white, occupied black, probabilities shaded between; unknown a
slightly blue mid grey so it stays distinguishable from p = 0.5), the trajectory as a
coloured polyline with start/end dots, each feature's 2σ ellipse outlined, a scale bar
and a north (+y) arrow. Cells are drawn as nearest-neighbour blocks so small maps are
readable: the long side is at least ~600 px and at most ~2400 px (larger maps are reduced
by taking the highest probability of each block, so thin obstacles survive).
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
from PIL import Image, ImageDraw, ImageFont

from formats.arrays import F64
from formats.map_types import FeatureTable, GridSpec, ProbabilityMap
from formats.writers.atomic import atomic_write_bytes
from formats.writers.ellipse import ellipse_polygons

__all__ = ["MAX_ELLIPSES", "MAX_SIDE_PX", "MIN_SIDE_PX", "render_map", "write_map_png"]

MIN_SIDE_PX = 600
MAX_SIDE_PX = 2400
MAX_ELLIPSES = 20_000

UNKNOWN_RGB = (150, 150, 165)
TRAJECTORY_RGB = (0, 114, 178)
ELLIPSE_RGB = (230, 97, 0)
START_RGB = (0, 158, 115)
END_RGB = (213, 94, 0)
TEXT_RGB = (0, 0, 0)
BACKGROUND_RGB = (255, 255, 255)

_MARGIN = 8  # px around the map
_STRIP = 44  # px below the map for the scale bar and north arrow



def _scale(long_side: int) -> tuple[int, int]:
    """``(reduce, enlarge)``: cells per block and pixels per block for a map's long side."""
    if long_side > MAX_SIDE_PX:
        return math.ceil(long_side / MAX_SIDE_PX), 1
    enlarge = max(1, min(math.ceil(MIN_SIDE_PX / long_side), MAX_SIDE_PX // long_side))
    return 1, enlarge


def _reduce_max(prob: npt.NDArray[np.float32], block: int) -> npt.NDArray[np.float32]:
    """Block-wise nan-max of ``prob`` (padding the high rows/cols with NaN)."""
    if block == 1:
        return prob
    h, w = prob.shape
    hp, wp = -(-h // block) * block, -(-w // block) * block
    padded = np.full((hp, wp), np.nan, dtype=np.float32)
    padded[:h, :w] = prob
    blocks = padded.reshape(hp // block, block, wp // block, block)
    # fmax-reduce instead of nanmax: no "All-NaN slice" warnings, NaN only if all NaN.
    reduced: npt.NDArray[np.float32] = np.fmax.reduce(np.fmax.reduce(blocks, axis=3), axis=1)
    return reduced


def _grey_rgb(prob: npt.NDArray[np.float32]) -> npt.NDArray[np.uint8]:
    """H×W×3 colours, image row 0 = max y: white free (p=0) … black occupied (p=1)."""
    p = np.clip(prob.astype(np.float64), 0.0, 1.0)
    grey = np.rint(255.0 * (1.0 - np.nan_to_num(p, nan=0.0))).astype(np.uint8)
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    rgb[np.isnan(prob)] = UNKNOWN_RGB
    return np.ascontiguousarray(rgb[::-1])


class _Frame:
    """World (m) → image pixel coordinates for the drawn map."""

    def __init__(self, grid: GridSpec, rows: int, px_per_cell: float, left: int, top: int):
        self.grid = grid
        self.ppc = px_per_cell
        self.left = left
        self.top = top
        self.rows = rows  # grid rows covered by the image (≥ grid.height after padding)

    def to_px(self, x: F64, y: F64) -> tuple[F64, F64]:
        g = self.grid
        u = self.left + (np.asarray(x) - g.origin_x) / g.resolution * self.ppc
        v = self.top + (self.rows - (np.asarray(y) - g.origin_y) / g.resolution) * self.ppc
        return u, v


def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    try:
        return ImageFont.load_default(size=size)
    except (OSError, ImportError):  # Pillow without FreeType: fixed bitmap font
        return ImageFont.load_default()


def _nice_length(max_m: float) -> float:
    """The largest 1, 2 or 5 × 10^k metres not above ``max_m``."""
    if not max_m > 0:
        return 0.0
    exp = math.floor(math.log10(max_m))
    for mant in (5.0, 2.0, 1.0):
        if mant * 10.0**exp <= max_m:
            return mant * 10.0**exp
    return 10.0 ** (exp - 1) * 5.0


def _draw_trajectory(draw: ImageDraw.ImageDraw, frame: _Frame, xy: np.ndarray) -> None:
    pts = np.asarray(xy, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"trajectory_xy must have shape (N, 2), got {pts.shape}")
    u, v = frame.to_px(pts[:, 0], pts[:, 1])
    finite = np.isfinite(u) & np.isfinite(v)
    if not finite.any():
        return
    # Runs of finite points: the polyline breaks at NaN poses instead of jumping the gap.
    edges = np.flatnonzero(np.diff(np.concatenate([[0], finite.astype(np.int8), [0]])))
    width = max(2, round(frame.ppc / 4)) if frame.ppc >= 8 else 2
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        su, sv = np.round(u[start:stop], 1), np.round(v[start:stop], 1)
        # Drop consecutive points that land on the same pixel: long logs stay cheap.
        keep = np.ones(su.shape, dtype=bool)
        keep[1:] = (np.abs(np.diff(su)) >= 0.5) | (np.abs(np.diff(sv)) >= 0.5)
        keep[-1] = True
        line = list(zip(su[keep].tolist(), sv[keep].tolist(), strict=True))
        if len(line) >= 2:
            draw.line(line, fill=TRAJECTORY_RGB, width=width, joint="curve")
    first, last = np.flatnonzero(finite)[[0, -1]]
    for idx, colour in ((first, START_RGB), (last, END_RGB)):
        cu, cv = float(u[idx]), float(v[idx])
        draw.ellipse((cu - 5, cv - 5, cu + 5, cv + 5), fill=colour, outline=(0, 0, 0))


def _draw_features(draw: ImageDraw.ImageDraw, frame: _Frame, features: FeatureTable) -> int:
    n = len(features)
    if n == 0:
        return 0
    order = np.arange(n)
    if n > MAX_ELLIPSES:
        # Most-measured features first; id breaks ties so the choice is deterministic.
        order = np.lexsort((features.id, -features.measured_times))[:MAX_ELLIPSES]
        order.sort()
    poly = ellipse_polygons(
        features.x[order],
        features.y[order],
        features.cov_xx[order],
        features.cov_xy[order],
        features.cov_yy[order],
        k=2.0,
        n=32,
    )
    u, v = frame.to_px(poly[..., 0], poly[..., 1])
    ok = np.isfinite(u).all(axis=1) & np.isfinite(v).all(axis=1)
    pts = np.round(np.stack([u, v], axis=-1), 1)
    drawn = 0
    for i in np.flatnonzero(ok):
        draw.polygon([tuple(p) for p in pts[i].tolist()], outline=ELLIPSE_RGB)
        drawn += 1
    return drawn


def _draw_scale_bar(
    draw: ImageDraw.ImageDraw, frame: _Frame, x0: int, y0: int, max_px: int
) -> None:
    px_per_m = frame.ppc / frame.grid.resolution
    length_m = _nice_length(max_px / px_per_m)
    if length_m <= 0:
        return
    length_px = round(length_m * px_per_m)
    font = _font(13)
    draw.rectangle((x0, y0, x0 + length_px, y0 + 6), fill=TEXT_RGB)
    draw.rectangle((x0 + length_px // 2, y0 + 1, x0 + length_px - 1, y0 + 5), fill=BACKGROUND_RGB)
    draw.text((x0, y0 + 10), f"{length_m:g} m", fill=TEXT_RGB, font=font)


def _draw_north(draw: ImageDraw.ImageDraw, cx: int, top: int, bottom: int) -> None:
    font = _font(13)
    draw.line((cx, bottom, cx, top + 8), fill=TEXT_RGB, width=2)
    draw.polygon([(cx, top), (cx - 5, top + 10), (cx + 5, top + 10)], fill=TEXT_RGB)
    draw.text((cx + 8, top), "N (+y)", fill=TEXT_RGB, font=font)


def render_map(
    snapshot: ProbabilityMap,
    *,
    trajectory_xy: np.ndarray | None,
    features: FeatureTable | None,
    title: str = "",
) -> Image.Image:
    """The map picture as an RGB Pillow image (see the module docstring)."""
    grid = snapshot.grid
    prob = np.asarray(snapshot.probability, dtype=np.float32)
    if prob.shape != grid.shape:
        raise ValueError(f"probability has shape {prob.shape}, grid is {grid.shape}")
    reduce, enlarge = _scale(max(grid.shape))
    reduced = _reduce_max(prob, reduce)
    rgb = _grey_rgb(reduced)
    if enlarge > 1:
        rgb = np.repeat(np.repeat(rgb, enlarge, axis=0), enlarge, axis=1)
    map_h, map_w = rgb.shape[:2]

    title_h = 24 if title else 0
    canvas_w = max(map_w + 2 * _MARGIN, 320)
    canvas_h = title_h + map_h + 2 * _MARGIN + _STRIP
    canvas = Image.new("RGB", (canvas_w, canvas_h), BACKGROUND_RGB)
    left, top = _MARGIN, _MARGIN + title_h
    canvas.paste(Image.fromarray(rgb, mode="RGB"), (left, top))
    draw = ImageDraw.Draw(canvas)
    draw.rectangle((left - 1, top - 1, left + map_w, top + map_h), outline=(60, 60, 60))

    frame = _Frame(grid, reduced.shape[0] * reduce, enlarge / reduce, left, top)
    if features is not None:
        _draw_features(draw, frame, features)
    if trajectory_xy is not None:
        _draw_trajectory(draw, frame, trajectory_xy)
    if title:
        draw.text((_MARGIN, 4), title, fill=TEXT_RGB, font=_font(16))
    strip_top = top + map_h + _MARGIN
    _draw_scale_bar(draw, frame, _MARGIN, strip_top + 6, max(40, (canvas_w - 120) // 3))
    _draw_north(draw, canvas_w - 70, strip_top + 2, strip_top + _STRIP - 6)
    return canvas


def write_map_png(
    path: Path,
    snapshot: ProbabilityMap,
    *,
    trajectory_xy: np.ndarray | None,
    features: FeatureTable | None,
    title: str = "",
) -> None:
    """Draw ``snapshot`` (plus trajectory (N×2, m, map frame) and feature 2σ ellipses) to a
    PNG at ``path``, atomically; the bytes depend only on the inputs (no time metadata)."""
    image = render_map(snapshot, trajectory_xy=trajectory_xy, features=features, title=title)
    buf = io.BytesIO()
    # No pnginfo: Pillow then writes no tEXt/tIME chunks; fixed compression → fixed bytes.
    image.save(buf, format="PNG", optimize=False, compress_level=6)
    atomic_write_bytes(Path(path), buf.getvalue())
