"""``map.png``: the map as a person reads it.

Occupancy in grey (free white, occupied black, probabilities shaded between; unknown a
slightly blue mid grey so it stays distinguishable from p = 0.5), the trajectory as a
coloured polyline with start/end dots, each feature's 2σ ellipse outlined; metre ticks on
both axes with a light coordinate grid, a legend, a scale bar and a north (+y) arrow.

The picture is cropped to the observed area (cells with any evidence, and the trajectory)
plus :data:`CROP_MARGIN_M`; map.pgm keeps the full grid nav2 needs. Cells are drawn as
nearest-neighbour blocks so small maps are readable: the long side is at least ~600 px and
at most ~2400 px (larger maps are reduced by taking the highest probability of each
block, so thin obstacles survive).
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

__all__ = [
    "CROP_MARGIN_M",
    "MAX_ELLIPSES",
    "MAX_SIDE_PX",
    "MIN_SIDE_PX",
    "MapFrame",
    "crop_to_observed",
    "render_map",
    "render_map_with_frame",
    "write_map_png",
]

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

CROP_MARGIN_M = 1.0  # m of grid kept around the observed area
GRID_RGB = (90, 140, 200)  # coordinate grid lines, blended over the map
GRID_ALPHA = 90

_MARGIN = 8  # px around everything
_AXIS_LEFT = 52  # px left of the map for the y tick labels
_AXIS_BOTTOM = 36  # px below the map for the x tick labels and axis title
_ROW = 22  # px per legend row



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


class MapFrame:
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


def _draw_trajectory(draw: ImageDraw.ImageDraw, frame: MapFrame, xy: np.ndarray) -> None:
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


def _draw_features(draw: ImageDraw.ImageDraw, frame: MapFrame, features: FeatureTable) -> int:
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
    draw: ImageDraw.ImageDraw, frame: MapFrame, x0: int, y0: int, max_px: int
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


def crop_to_observed(
    prob: npt.NDArray[np.float32], grid: GridSpec, trajectory_xy: np.ndarray | None
) -> tuple[npt.NDArray[np.float32], GridSpec]:
    """The part of the grid with evidence (non-NaN cells) or trajectory, plus
    CROP_MARGIN_M on each side, as (probability, grid); the whole grid if neither."""
    rows = np.flatnonzero(~np.isnan(prob).all(axis=1))
    cols = np.flatnonzero(~np.isnan(prob).all(axis=0))
    lo_r, hi_r, lo_c, hi_c = [], [], [], []
    if rows.size:
        lo_r.append(int(rows[0]))
        hi_r.append(int(rows[-1]))
        lo_c.append(int(cols[0]))
        hi_c.append(int(cols[-1]))
    if trajectory_xy is not None:
        pts = np.asarray(trajectory_xy, dtype=np.float64).reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        if pts.size:
            c = np.floor((pts[:, 0] - grid.origin_x) / grid.resolution).astype(np.int64)
            r = np.floor((pts[:, 1] - grid.origin_y) / grid.resolution).astype(np.int64)
            lo_r.append(int(r.min()))
            hi_r.append(int(r.max()))
            lo_c.append(int(c.min()))
            hi_c.append(int(c.max()))
    if not lo_r:
        return prob, grid
    pad = math.ceil(CROP_MARGIN_M / grid.resolution - 1e-9)
    r0, r1 = max(min(lo_r) - pad, 0), min(max(hi_r) + pad + 1, grid.height)
    c0, c1 = max(min(lo_c) - pad, 0), min(max(hi_c) + pad + 1, grid.width)
    if r0 >= r1 or c0 >= c1:  # trajectory entirely off the grid
        return prob, grid
    sub = GridSpec(
        round(grid.origin_x + c0 * grid.resolution, 9), round(grid.origin_y + r0 * grid.resolution, 9),
        grid.resolution, c1 - c0, r1 - r0,
    )
    return prob[r0:r1, c0:c1], sub


def _tick_step(span_m: float, target: int = 6) -> float:
    """A round step (1, 2 or 5 × 10^k m) giving about ``target`` ticks over ``span_m``."""
    raw = max(span_m, 1e-9) / target
    exp = math.floor(math.log10(raw))
    return next(m * 10.0**exp for m in (1.0, 2.0, 5.0, 10.0) if m * 10.0**exp >= raw)


def _tick_label(v: float, step: float) -> str:
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    text = f"{v:.{decimals}f}"
    return "0" if float(text) == 0 else text  # ASCII minus: the default font has no U+2212


def _draw_axes(canvas: Image.Image, frame: MapFrame, map_w: int, map_h: int) -> None:
    """Metre ticks on the bottom and left edges, a light grid over the map, axis titles."""
    g = frame.grid
    x0, x1 = g.origin_x, g.origin_x + map_w / frame.ppc * g.resolution
    y_top = g.origin_y + frame.rows * g.resolution
    y0 = y_top - map_h / frame.ppc * g.resolution
    step = _tick_step(max(x1 - x0, y_top - y0), target=8)
    font = _font(12)
    overlay = Image.new("RGBA", canvas.size, (0, 0, 0, 0))
    grid_draw = ImageDraw.Draw(overlay)
    draw = ImageDraw.Draw(canvas)
    left, top = frame.left, frame.top
    bottom, right = top + map_h, left + map_w
    for k in range(math.ceil(x0 / step - 1e-9), math.floor(x1 / step + 1e-9) + 1):
        u = float(frame.to_px(np.array([k * step]), np.array([0.0]))[0][0])
        grid_draw.line((u, top, u, bottom - 1), fill=(*GRID_RGB, GRID_ALPHA))
        draw.line((u, bottom, u, bottom + 4), fill=TEXT_RGB)
        draw.text((u, bottom + 6), _tick_label(k * step, step), fill=TEXT_RGB, font=font,
                  anchor="ma")
    for k in range(math.ceil(y0 / step - 1e-9), math.floor(y_top / step + 1e-9) + 1):
        v = float(frame.to_px(np.array([0.0]), np.array([k * step]))[1][0])
        grid_draw.line((left, v, right - 1, v), fill=(*GRID_RGB, GRID_ALPHA))
        draw.line((left - 5, v, left - 1, v), fill=TEXT_RGB)
        draw.text((left - 7, v), _tick_label(k * step, step), fill=TEXT_RGB, font=font,
                  anchor="rm")
    canvas.paste(Image.alpha_composite(canvas.convert("RGBA"), overlay).convert("RGB"))
    draw = ImageDraw.Draw(canvas)
    draw.text(((left + right) / 2, bottom + 20), "x (m)", fill=TEXT_RGB, font=font, anchor="ma")
    draw.text((left - 7, top - 4), "y (m)", fill=TEXT_RGB, font=font, anchor="rd")


def _legend_items(trajectory: bool, features: bool) -> list[tuple[str, str]]:
    items = [("free", "free"), ("occupied", "occupied"), ("unknown", "unknown (not observed)")]
    if trajectory:
        items += [("trajectory", "trajectory"), ("start", "start"), ("end", "end")]
    if features:
        items.append(("ellipse", "feature ellipse (2 sigma)"))
    return items


def _draw_swatch(draw: ImageDraw.ImageDraw, kind: str, x: int, y: int) -> None:
    box = (x, y + 3, x + 14, y + 15)
    if kind in ("free", "occupied", "unknown"):
        fill = {"free": BACKGROUND_RGB, "occupied": (0, 0, 0), "unknown": UNKNOWN_RGB}[kind]
        draw.rectangle(box, fill=fill, outline=(60, 60, 60))
    elif kind == "trajectory":
        draw.line((x, y + 9, x + 14, y + 9), fill=TRAJECTORY_RGB, width=3)
    elif kind in ("start", "end"):
        colour = START_RGB if kind == "start" else END_RGB
        draw.ellipse((x + 2, y + 4, x + 12, y + 14), fill=colour, outline=(0, 0, 0))
    else:
        draw.ellipse((x - 2, y + 5, x + 16, y + 13), outline=ELLIPSE_RGB, width=2)


def _legend_layout(items: list[tuple[str, str]], width: int) -> list[list[tuple[str, str, int]]]:
    """Items in rows that fit ``width``: (kind, text, text width in px) per item."""
    font = _font(12)
    rows: list[list[tuple[str, str, int]]] = [[]]
    used = 0
    for kind, text in items:
        tw = math.ceil(font.getlength(text))
        need = 20 + tw + 16
        if rows[-1] and used + need > width:
            rows.append([])
            used = 0
        rows[-1].append((kind, text, tw))
        used += need
    return rows


def _draw_legend(draw: ImageDraw.ImageDraw, rows: list[list[tuple[str, str, int]]],
                 x0: int, y0: int) -> None:
    font = _font(12)
    for i, row in enumerate(rows):
        x, y = x0, y0 + i * _ROW
        for kind, text, tw in row:
            _draw_swatch(draw, kind, x, y)
            draw.text((x + 20, y + 3), text, fill=TEXT_RGB, font=font)
            x += 20 + tw + 16


def render_map_with_frame(
    snapshot: ProbabilityMap,
    *,
    trajectory_xy: np.ndarray | None,
    features: FeatureTable | None,
    title: str = "",
    crop: bool = True,
) -> tuple[Image.Image, MapFrame, tuple[int, int]]:
    """The picture, where its map lies (world → pixel) and the map area's (width, height)
    in px. ``crop``: draw only the observed area plus CROP_MARGIN_M (default)."""
    grid = snapshot.grid
    prob = np.asarray(snapshot.probability, dtype=np.float32)
    if prob.shape != grid.shape:
        raise ValueError(f"probability has shape {prob.shape}, grid is {grid.shape}")
    if trajectory_xy is not None:
        pts = np.asarray(trajectory_xy)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(f"trajectory_xy must have shape (N, 2), got {pts.shape}")
    if crop:
        prob, grid = crop_to_observed(prob, grid, trajectory_xy)
    reduce, enlarge = _scale(max(grid.shape))
    reduced = _reduce_max(prob, reduce)
    rgb = _grey_rgb(reduced)
    if enlarge > 1:
        rgb = np.repeat(np.repeat(rgb, enlarge, axis=0), enlarge, axis=1)
    map_h, map_w = rgb.shape[:2]

    title_h = 26 if title else 0
    left, top = _MARGIN + _AXIS_LEFT, _MARGIN + title_h + 16  # 16: room for "y (m)"
    canvas_w = max(left + map_w + 2 * _MARGIN, 560)
    has_traj = trajectory_xy is not None and len(trajectory_xy) > 0
    has_feat = features is not None and len(features) > 0
    legend = _legend_layout(_legend_items(has_traj, has_feat), canvas_w - 2 * _MARGIN)
    strip_top = top + map_h + _AXIS_BOTTOM
    canvas_h = strip_top + len(legend) * _ROW + 44 + _MARGIN
    canvas = Image.new("RGB", (canvas_w, canvas_h), BACKGROUND_RGB)
    canvas.paste(Image.fromarray(rgb, mode="RGB"), (left, top))
    frame = MapFrame(grid, reduced.shape[0] * reduce, enlarge / reduce, left, top)
    _draw_axes(canvas, frame, map_w, map_h)
    draw = ImageDraw.Draw(canvas)
    # Overlays are clipped to the map area: features and poses outside the crop are cut.
    layer = Image.new("RGB", (map_w, map_h))
    layer.paste(canvas.crop((left, top, left + map_w, top + map_h)))
    shifted = MapFrame(grid, frame.rows, frame.ppc, 0, 0)
    layer_draw = ImageDraw.Draw(layer)
    if features is not None:
        _draw_features(layer_draw, shifted, features)
    if trajectory_xy is not None:
        _draw_trajectory(layer_draw, shifted, trajectory_xy)
    canvas.paste(layer, (left, top))
    draw.rectangle((left - 1, top - 1, left + map_w, top + map_h), outline=(60, 60, 60))
    if title:
        draw.text((_MARGIN, 6), title, fill=TEXT_RGB, font=_font(16))
    _draw_legend(draw, legend, _MARGIN, strip_top)
    bar_top = strip_top + len(legend) * _ROW + 6
    _draw_scale_bar(draw, frame, _MARGIN, bar_top, max(40, (canvas_w - 120) // 3))
    _draw_north(draw, canvas_w - 70, bar_top - 2, bar_top + 34)
    return canvas, frame, (map_w, map_h)


def render_map(
    snapshot: ProbabilityMap,
    *,
    trajectory_xy: np.ndarray | None,
    features: FeatureTable | None,
    title: str = "",
    crop: bool = True,
) -> Image.Image:
    """The map picture as an RGB Pillow image (see the module docstring)."""
    image, _frame, _size = render_map_with_frame(
        snapshot, trajectory_xy=trajectory_xy, features=features, title=title, crop=crop
    )
    return image


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
