"""A picture of what changed between a golden map and a new one (``regress --diff-dir``).

Both nav2 maps are read as map_server would (classes occupied / free / unknown) and laid
on one grid: the golden's resolution and alignment, widened to cover both maps; each cell
takes the class of the map cell holding its centre (unknown outside a map). Drawn: the
golden map in grey (free white, occupied grey, unknown :data:`~formats.writers.map_png.UNKNOWN_RGB`),
cells occupied now but not in the golden in :data:`NEW_RGB`, cells occupied in the golden
but not now in :data:`GONE_RGB`, the new run's path over it, metre axes, a legend with the
two counts (in golden cells) and a scale bar. Cropped to the observed area and sized as
``map.png`` (:mod:`formats.writers.map_png`). Deterministic bytes.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from PIL import Image, ImageDraw

from formats.map_types import GridSpec
from formats.writers.atomic import atomic_write_bytes
from formats.writers.map_png import (
    BACKGROUND_RGB,
    TEXT_RGB,
    TRAJECTORY_RGB,
    MapFrame,
    _draw_axes,
    _draw_scale_bar,
    _font,
    _grey_rgb,
    _reduce_max,
    _scale,
    crop_to_observed,
)
from formats.writers.nav2_map import FREE, OCCUPIED, UNKNOWN, Nav2Map, load_nav2_map

__all__ = ["GONE_RGB", "NEW_RGB", "MapDiff", "map_diff", "render_map_diff",
           "write_map_diff_png"]

NEW_RGB = (213, 94, 0)  # vermillion: occupied now, not in the golden
GONE_RGB = (0, 158, 115)  # bluish green: occupied in the golden, not now
GOLDEN_OCCUPIED_P = 0.6  # grey level of the golden's occupied cells (so colours stand out)
_MARGIN, _AXIS_LEFT, _AXIS_BOTTOM, _ROW = 8, 52, 36, 22


@dataclass(frozen=True)
class MapDiff:
    """Both maps' classes on one grid (row 0 at min y) and the changed cells."""

    grid: GridSpec
    golden: npt.NDArray[np.int8]
    current: npt.NDArray[np.int8]

    @property
    def new_occupied(self) -> npt.NDArray[np.bool_]:
        out: npt.NDArray[np.bool_] = (self.current == OCCUPIED) & (self.golden != OCCUPIED)
        return out

    @property
    def no_longer_occupied(self) -> npt.NDArray[np.bool_]:
        out: npt.NDArray[np.bool_] = (self.golden == OCCUPIED) & (self.current != OCCUPIED)
        return out


def _sample(m: Nav2Map, grid: GridSpec) -> npt.NDArray[np.int8]:
    """``m``'s class at each cell centre of ``grid`` (unknown outside ``m``)."""
    g = m.grid
    xs = grid.origin_x + (np.arange(grid.width) + 0.5) * grid.resolution
    ys = grid.origin_y + (np.arange(grid.height) + 0.5) * grid.resolution
    cols = np.floor((xs - g.origin_x) / g.resolution).astype(np.int64)
    rows = np.floor((ys - g.origin_y) / g.resolution).astype(np.int64)
    ok_c, ok_r = (cols >= 0) & (cols < g.width), (rows >= 0) & (rows < g.height)
    out = np.full(grid.shape, UNKNOWN, dtype=np.int8)
    sub = m.classes[np.ix_(rows[ok_r], cols[ok_c])]
    out[np.ix_(np.flatnonzero(ok_r), np.flatnonzero(ok_c))] = sub
    return out


def map_diff(golden: Nav2Map, current: Nav2Map) -> MapDiff:
    """Both maps on the golden's grid widened to cover the current one."""
    g, c = golden.grid, current.grid
    res = g.resolution
    lo_c = min(0, math.floor((c.origin_x - g.origin_x) / res + 1e-9))
    lo_r = min(0, math.floor((c.origin_y - g.origin_y) / res + 1e-9))
    hi_c = max(g.width, math.ceil((c.origin_x + c.width * c.resolution - g.origin_x) / res - 1e-9))
    hi_r = max(g.height, math.ceil((c.origin_y + c.height * c.resolution - g.origin_y) / res
                                   - 1e-9))
    grid = GridSpec(round(g.origin_x + lo_c * res, 9), round(g.origin_y + lo_r * res, 9), res,
                    hi_c - lo_c, hi_r - lo_r)
    return MapDiff(grid, _sample(golden, grid), _sample(current, grid))


def render_map_diff(diff: MapDiff, trajectory_xy: np.ndarray | None, title: str = "") -> Image.Image:
    """The picture (see the module docstring) as an RGB Pillow image."""
    new, gone = diff.new_occupied, diff.no_longer_occupied
    prob = np.full(diff.grid.shape, np.nan, dtype=np.float32)
    prob[diff.golden == FREE] = 0.0
    prob[diff.golden == OCCUPIED] = GOLDEN_OCCUPIED_P
    seen = prob.copy()
    seen[new | gone] = 0.5  # changed cells are in the picture even where the golden is unknown
    _, sub = crop_to_observed(seen, diff.grid, trajectory_xy)
    c0 = round((sub.origin_x - diff.grid.origin_x) / sub.resolution)
    r0 = round((sub.origin_y - diff.grid.origin_y) / sub.resolution)
    window = (slice(r0, r0 + sub.height), slice(c0, c0 + sub.width))
    reduce, enlarge = _scale(max(sub.shape))
    rgb = _grey_rgb(_reduce_max(prob[window], reduce))
    for mask, colour in ((gone, GONE_RGB), (new, NEW_RGB)):
        painted = _reduce_max(mask[window].astype(np.float32), reduce)[::-1] > 0
        rgb[painted] = colour
    if enlarge > 1:
        rgb = np.repeat(np.repeat(rgb, enlarge, axis=0), enlarge, axis=1)
    map_h, map_w = rgb.shape[:2]
    title_h = 26 if title else 0
    left, top = _MARGIN + _AXIS_LEFT, _MARGIN + title_h + 16
    width = max(left + map_w + 2 * _MARGIN, 560)
    legend = [(NEW_RGB, f"newly occupied: {int(new.sum())} cells"),
              (GONE_RGB, f"no longer occupied: {int(gone.sum())} cells"),
              ((0, 0, 0), "golden map: free white, occupied dark grey, unknown blue-grey")]
    if trajectory_xy is not None:
        legend.append((TRAJECTORY_RGB, "path (new run)"))
    strip = top + map_h + _AXIS_BOTTOM
    canvas = Image.new("RGB", (width, strip + len(legend) * _ROW + 40 + _MARGIN), BACKGROUND_RGB)
    canvas.paste(Image.fromarray(np.ascontiguousarray(rgb), mode="RGB"), (left, top))
    frame = MapFrame(sub, -(-sub.height // reduce) * reduce, enlarge / reduce, left, top)
    _draw_axes(canvas, frame, map_w, map_h)
    draw = ImageDraw.Draw(canvas)
    if trajectory_xy is not None and len(trajectory_xy) >= 2:
        u, v = frame.to_px(trajectory_xy[:, 0], trajectory_xy[:, 1])
        pts = [(float(a), float(b)) for a, b in zip(np.round(u, 1), np.round(v, 1), strict=True)
               if math.isfinite(a) and math.isfinite(b)]
        layer = canvas.crop((left, top, left + map_w, top + map_h))
        ImageDraw.Draw(layer).line([(a - left, b - top) for a, b in pts], fill=TRAJECTORY_RGB,
                                   width=2)
        canvas.paste(layer, (left, top))
    draw.rectangle((left - 1, top - 1, left + map_w, top + map_h), outline=(60, 60, 60))
    if title:
        draw.text((_MARGIN, 6), title, fill=TEXT_RGB, font=_font(16))
    font = _font(12)
    for i, (colour, text) in enumerate(legend):
        y = strip + i * _ROW
        if colour == (0, 0, 0):
            draw.rectangle((_MARGIN, y + 3, _MARGIN + 6, y + 15), fill=BACKGROUND_RGB,
                           outline=(60, 60, 60))
            draw.rectangle((_MARGIN + 7, y + 3, _MARGIN + 14, y + 15),
                           fill=(102, 102, 102), outline=(60, 60, 60))
        elif colour == TRAJECTORY_RGB:
            draw.line((_MARGIN, y + 9, _MARGIN + 14, y + 9), fill=colour, width=3)
        else:
            draw.rectangle((_MARGIN, y + 3, _MARGIN + 14, y + 15), fill=colour,
                           outline=(60, 60, 60))
        draw.text((_MARGIN + 20, y + 3), text, fill=TEXT_RGB, font=font)
    _draw_scale_bar(draw, frame, _MARGIN, strip + len(legend) * _ROW + 6,
                    max(40, (width - 120) // 3))
    return canvas


def write_map_diff_png(path: Path, golden_yaml: Path, current_yaml: Path, *,
                       trajectory_csv: Path | None = None, title: str = "") -> MapDiff:
    """Draw the diff of two nav2 maps (plus the path of ``trajectory_csv`` when it
    exists) to a PNG at ``path``, atomically; returns the diff."""
    from formats.writers.trajectory_csv import read_trajectory

    diff = map_diff(load_nav2_map(golden_yaml), load_nav2_map(current_yaml))
    xy = None
    if trajectory_csv is not None and Path(trajectory_csv).is_file():
        xy = read_trajectory(Path(trajectory_csv)).xy
    image = render_map_diff(diff, xy, title)
    buf = io.BytesIO()
    image.save(buf, format="PNG", optimize=False, compress_level=6)  # no time chunks
    atomic_write_bytes(Path(path), buf.getvalue())
    return diff
