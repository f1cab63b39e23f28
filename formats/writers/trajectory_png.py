"""``trajectory.png``: the odometry against the refined trajectory (``run --refine-poses``).

Both tracks as polylines on white, the odometry grey and the refined poses blue (and the
graph model's loop closures as red segments between the refined anchors they join), with a
start dot, a 1 m grid, a legend and the figure's scale in the title; +x right, +y up
(REP 103). Deterministic: the same tracks give the same bytes.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from formats.arrays import F64
from formats.writers.atomic import atomic_write_bytes

SIZE = 800  # px, long side of the drawing area
MARGIN = 40
ODOMETRY = (150, 150, 150)
REFINED = (30, 90, 200)
CLOSURE = (210, 40, 40)


def _font() -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    try:
        return ImageFont.load_default(size=14)
    except (OSError, ImportError):
        return ImageFont.load_default()


def trajectory_png_bytes(odometry_xy: F64, refined_xy: F64, title: str = "",
                         closures: F64 | None = None) -> bytes:
    """The PNG of the two tracks (N×2 arrays, m) and the loop closures (M×4: the two
    joined anchors' x, y, m)."""
    pts = np.concatenate([odometry_xy, refined_xy])
    x0, y0 = pts.min(axis=0) - 0.5
    x1, y1 = pts.max(axis=0) + 0.5
    scale = SIZE / max(x1 - x0, y1 - y0)  # px per m
    w = math.ceil((x1 - x0) * scale) + 2 * MARGIN
    h = math.ceil((y1 - y0) * scale) + 2 * MARGIN
    img = Image.new("RGB", (w, h), (255, 255, 255))
    d = ImageDraw.Draw(img)

    def px(xy: F64) -> list[tuple[float, float]]:
        u = MARGIN + (xy[:, 0] - x0) * scale
        v = h - MARGIN - (xy[:, 1] - y0) * scale
        return list(zip(u.round(2).tolist(), v.round(2).tolist(), strict=True))

    for gx in np.arange(math.ceil(x0), math.floor(x1) + 1):
        u = MARGIN + (gx - x0) * scale
        d.line([(u, MARGIN), (u, h - MARGIN)], fill=(235, 235, 235))
    for gy in np.arange(math.ceil(y0), math.floor(y1) + 1):
        v = h - MARGIN - (gy - y0) * scale
        d.line([(MARGIN, v), (w - MARGIN, v)], fill=(235, 235, 235))
    for e in (closures if closures is not None else np.empty((0, 4))):
        d.line(px(e.reshape(2, 2)), fill=CLOSURE, width=1)
    for xy, colour in ((odometry_xy, ODOMETRY), (refined_xy, REFINED)):
        if xy.shape[0] >= 2:
            d.line(px(xy), fill=colour, width=2)
        if xy.shape[0]:
            (u, v), = px(xy[:1])
            d.ellipse([u - 4, v - 4, u + 4, v + 4], fill=colour)
    font = _font()
    d.text((MARGIN, 8), f"{title}  (grid 1 m)".strip(), fill=(0, 0, 0), font=font)
    d.line([(w - 230, 16), (w - 200, 16)], fill=ODOMETRY, width=3)
    d.text((w - 195, 8), "odometry", fill=(0, 0, 0), font=font)
    d.line([(w - 115, 16), (w - 85, 16)], fill=REFINED, width=3)
    d.text((w - 80, 8), "refined", fill=(0, 0, 0), font=font)
    if closures is not None and closures.shape[0]:
        d.line([(w - 345, 16), (w - 315, 16)], fill=CLOSURE, width=3)
        d.text((w - 310, 8), "loop closure", fill=(0, 0, 0), font=font)
    buf = io.BytesIO()
    img.save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def write_trajectory_png(path: Path, odometry_xy: F64, refined_xy: F64, title: str = "",
                         closures: F64 | None = None) -> None:
    """Write ``trajectory.png`` atomically."""
    atomic_write_bytes(path, trajectory_png_bytes(odometry_xy, refined_xy, title, closures))
