"""Simulated worlds: line segments and circles in the world (map) frame, metres.

A :class:`World` is loaded from a small TOML file (``[[segment]]``, ``[[circle]]``,
``[[polygon]]``) or from a nav2 occupancy map, whose occupied cells become the segments
that separate them from non-occupied cells. ``World.rasterize`` gives the ground-truth
probability grid that simulated maps are compared with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from formats.arrays import F32, F64
from formats.errors import ConfigError
from formats.map_types import GridSpec
from formats.ranges import Range
from formats.toml_file import read_toml

# A simulated world is a building or a site: its coordinates within 10 km of its origin,
# its trunks and pillars at most 1 km across, its truth grid at most as many cells as a
# run's grid may have (grid.max_cells' default).
WORLD_M = Range(-1e4, 1e4, "m")
RADIUS_M = Range(0, 500, "m", lo_open=True)
MAX_WORLD_CELLS = 40_000_000

# Rasterising samples each segment this many times per cell: a segment that clips a cell
# corner by less than resolution/8 may leave that cell free (documented approximation).
_SAMPLES_PER_CELL = 8


@dataclass(frozen=True)
class World:
    """Obstacles of a 2-D world (metres, world frame).

    ``segments``: N×4 rows ``(x0, y0, x1, y1)``; ``circles``: M×3 rows ``(cx, cy, r)``.
    ``bounds``: ``(xmin, ymin, xmax, ymax)``; the bounding box of the obstacles when the
    world file gives none.
    """

    segments: F64
    circles: F64
    name: str = ""
    bounds: tuple[float, float, float, float] = field(default=(0.0, 0.0, 0.0, 0.0))

    def __post_init__(self) -> None:
        seg = np.asarray(self.segments, dtype=np.float64).reshape(-1, 4)
        cir = np.asarray(self.circles, dtype=np.float64).reshape(-1, 3)
        object.__setattr__(self, "segments", seg)
        object.__setattr__(self, "circles", cir)
        if self.bounds == (0.0, 0.0, 0.0, 0.0):
            object.__setattr__(self, "bounds", _obstacle_bounds(seg, cir))

    def grid(self, resolution: float, margin: float = 0.0) -> GridSpec:
        """The grid covering ``bounds`` plus ``margin`` (m) at ``resolution`` (m)."""
        x0, y0, x1, y1 = self.bounds
        cells = ((x1 - x0 + 2 * margin) / resolution + 2) * ((y1 - y0 + 2 * margin) / resolution + 2)
        if not cells <= MAX_WORLD_CELLS:
            raise ConfigError(
                f"world of {x1 - x0:g} x {y1 - y0:g} m needs {cells:.3g} cells at {resolution:g} m,"
                f" more than {MAX_WORLD_CELLS}"
            )
        return GridSpec.covering(x0 - margin, y0 - margin, x1 + margin, y1 + margin, resolution)

    def rasterize(self, grid: GridSpec) -> F32:
        """Ground truth: float32 H×W, 1.0 where a cell holds an obstacle surface, else 0.0.

        Row 0 is the minimum y. Cells crossed by a segment and cells that intersect a
        circle's disc (trunks are solid) are 1.0; everything else is 0.0 (free).
        """
        out = np.zeros(grid.shape, dtype=np.float32)
        res = grid.resolution
        seg = self.segments
        if seg.shape[0]:
            length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
            n = np.ceil(length / res * _SAMPLES_PER_CELL).astype(np.int64) + 1
            owner = np.repeat(np.arange(seg.shape[0]), n)
            first = np.cumsum(n) - n
            k = np.arange(owner.shape[0]) - first[owner]
            s = k / np.maximum(n[owner] - 1, 1)
            px = seg[owner, 0] + s * (seg[owner, 2] - seg[owner, 0])
            py = seg[owner, 1] + s * (seg[owner, 3] - seg[owner, 1])
            _mark(out, grid, px, py)
        cir = self.circles
        if cir.shape[0]:
            # A window of cells around each circle, all circles at once (M×win×win).
            win = int(np.ceil(2 * cir[:, 2].max() / res)) + 3
            c0 = np.floor((cir[:, 0] - cir[:, 2] - grid.origin_x) / res).astype(np.int64) - 1
            r0 = np.floor((cir[:, 1] - cir[:, 2] - grid.origin_y) / res).astype(np.int64) - 1
            off = np.arange(win)
            cols = c0[:, None, None] + off[None, None, :]
            rows = r0[:, None, None] + off[None, :, None]
            cols, rows = np.broadcast_arrays(cols, rows)
            # Closest point of each cell to the circle's centre.
            xlo = grid.origin_x + cols * res
            ylo = grid.origin_y + rows * res
            qx = np.clip(cir[:, 0, None, None], xlo, xlo + res)
            qy = np.clip(cir[:, 1, None, None], ylo, ylo + res)
            hit = np.hypot(qx - cir[:, 0, None, None], qy - cir[:, 1, None, None])
            hit = hit < cir[:, 2, None, None]
            inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
            sel = hit & inside
            out[rows[sel], cols[sel]] = 1.0
        return out



def segment_distances(seg: F64, ox: F64, oy: F64, ux: F64, uy: F64) -> F64:
    """(N, M) distance along each of N rays (origin ``ox, oy``, unit direction ``ux, uy``)
    to each of M segments ``seg`` (x0, y0, x1, y1); inf where the ray misses it."""
    ax, ay = seg[None, :, 0], seg[None, :, 1]
    ex, ey = seg[None, :, 2] - ax, seg[None, :, 3] - ay
    wx, wy = ax - ox[:, None], ay - oy[:, None]
    denom = ux[:, None] * ey - uy[:, None] * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / denom
        s = (wx * uy[:, None] - wy * ux[:, None]) / denom
    ok = (denom != 0) & (t > 0) & (s >= 0) & (s <= 1)
    return np.where(ok, t, np.inf)


def circle_distances(cir: F64, ox: F64, oy: F64, ux: F64, uy: F64) -> tuple[F64, F64]:
    """(N, M) distance along each of N rays (origin ``ox, oy``, unit direction ``ux, uy``)
    to each of M circles ``cir`` (x, y, r), inf where the ray misses it or starts inside it,
    and ``sqrt(disc) = |u · (p − c)|``, the radial component at the hit (r·cos incidence)."""
    fx, fy = ox[:, None] - cir[None, :, 0], oy[:, None] - cir[None, :, 1]
    b = ux[:, None] * fx + uy[:, None] * fy
    c = fx * fx + fy * fy - cir[None, :, 2] ** 2
    disc = b * b - c
    with np.errstate(invalid="ignore"):
        root = np.sqrt(disc)
    t = -b - root
    # Origins inside a circle (c < 0) see nothing of it.
    return np.where((disc >= 0) & (c > 0) & (t > 0), t, np.inf), root

def _mark(out: F32, grid: GridSpec, px: F64, py: F64) -> None:
    col = np.floor((px - grid.origin_x) / grid.resolution).astype(np.int64)
    row = np.floor((py - grid.origin_y) / grid.resolution).astype(np.int64)
    ok = (row >= 0) & (row < grid.height) & (col >= 0) & (col < grid.width)
    out[row[ok], col[ok]] = 1.0


def _obstacle_bounds(seg: F64, cir: F64) -> tuple[float, float, float, float]:
    xs = [seg[:, 0], seg[:, 2], cir[:, 0] - cir[:, 2], cir[:, 0] + cir[:, 2]]
    ys = [seg[:, 1], seg[:, 3], cir[:, 1] - cir[:, 2], cir[:, 1] + cir[:, 2]]
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    if x.size == 0:
        return (0.0, 0.0, 0.0, 0.0)
    return (float(x.min()), float(y.min()), float(x.max()), float(y.max()))


# --------------------------------------------------------------------------- loading


def load_world(path: str | Path) -> World:
    """A world from a TOML world file, or from a nav2 map (``.yaml``)."""
    p = Path(path)
    if p.suffix.lower() in (".yaml", ".yml"):
        from formats.writers.nav2_map import load_nav2_map

        nav2 = load_nav2_map(p)
        world = world_from_occupancy(np.asarray(nav2.classes), nav2.grid)
        return World(world.segments, world.circles, name=p.stem, bounds=world.bounds)
    data = read_toml(p, "world")
    try:
        return world_from_dict(data, default_name=p.stem)
    except ConfigError as err:
        raise ConfigError(err.reason, p) from err


def world_from_dict(data: dict[str, Any], default_name: str = "") -> World:
    """A world from parsed TOML: ``segment``, ``circle``, ``polygon`` arrays of tables."""
    known = {"name", "bounds", "segment", "circle", "polygon"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f"unknown key '{unknown[0]}' (known: {', '.join(sorted(known))})")
    segs: list[list[float]] = []
    circles: list[list[float]] = []
    for i, item in enumerate(_tables(data, "segment")):
        key = f"segment[{i}]"
        a = _point(item.get("from"), f"{key}.from")
        b = _point(item.get("to"), f"{key}.to")
        segs.append([*a, *b])
    for i, item in enumerate(_tables(data, "circle")):
        key = f"circle[{i}]"
        c = _point(item.get("center"), f"{key}.center")
        r = _number(item.get("radius"), f"{key}.radius", RADIUS_M)
        circles.append([*c, r])
    for i, item in enumerate(_tables(data, "polygon")):
        key = f"polygon[{i}].points"
        pts_raw = item.get("points")
        if not isinstance(pts_raw, list) or len(pts_raw) < 2:
            raise ConfigError(f"'{key}' must be an array of at least 2 [x, y] points")
        pts = [_point(p, f"{key}[{j}]") for j, p in enumerate(pts_raw)]
        # Closed: the last point joins the first.
        for j in range(len(pts)):
            a, b = pts[j], pts[(j + 1) % len(pts)]
            if a != b:
                segs.append([*a, *b])
    name = data.get("name", default_name)
    if not isinstance(name, str):
        raise ConfigError(f"'name' must be a string, got {name!r}")
    bounds_raw = data.get("bounds")
    seg_arr = np.array(segs, dtype=np.float64).reshape(-1, 4)
    cir_arr = np.array(circles, dtype=np.float64).reshape(-1, 3)
    if seg_arr.shape[0] == 0 and cir_arr.shape[0] == 0:
        raise ConfigError("world has no obstacles (no segment, circle or polygon)")
    if bounds_raw is None:
        return World(seg_arr, cir_arr, name=name)
    if not isinstance(bounds_raw, list) or len(bounds_raw) != 4:
        raise ConfigError(f"'bounds' must be [xmin, ymin, xmax, ymax], got {bounds_raw!r}")
    b4 = [_number(v, f"bounds[{j}]") for j, v in enumerate(bounds_raw)]
    if not (b4[0] < b4[2] and b4[1] < b4[3]):
        raise ConfigError(f"'bounds' must have xmin < xmax and ymin < ymax, got {b4!r}")
    return World(seg_arr, cir_arr, name=name, bounds=(b4[0], b4[1], b4[2], b4[3]))


def _tables(data: dict[str, Any], key: str) -> list[dict[str, Any]]:
    items = data.get(key, [])
    if not isinstance(items, list) or not all(isinstance(t, dict) for t in items):
        raise ConfigError(f"'{key}' must be an array of tables ([[{key}]])")
    return items


def _number(v: Any, key: str, rng: Range = WORLD_M) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"'{key}' must be a finite number, got {v!r}")
    if not rng.holds(v):
        raise ConfigError(f"'{key}' {rng.rule()}, got {v!r}")
    return float(v)


def _point(v: Any, key: str) -> list[float]:
    if not isinstance(v, list) or len(v) != 2:
        raise ConfigError(f"'{key}' must be [x, y], got {v!r}")
    return [_number(v[0], key), _number(v[1], key)]


def world_from_occupancy(classes: npt.ArrayLike, grid: GridSpec, name: str = "") -> World:
    """Segments bounding the occupied cells of a class grid (1 occupied, 0 free, −1 unknown).

    Row 0 is the minimum y. An edge between an occupied cell and a non-occupied one (or the
    grid border) becomes a segment; collinear neighbouring edges are merged into one.
    """
    occ = np.asarray(classes) == 1
    h, w = occ.shape
    pad = np.zeros((h + 2, w + 2), dtype=bool)
    pad[1:-1, 1:-1] = occ
    res, ox, oy = grid.resolution, grid.origin_x, grid.origin_y
    # Vertical edges: x = ox + c·res for c in 0..w, one per row r.
    vert = pad[1:-1, :-1] != pad[1:-1, 1:]  # h × (w+1)
    c, r0, r1 = _runs(vert.T)  # runs along rows for a fixed column
    v = np.stack([ox + c * res, oy + r0 * res, ox + c * res, oy + r1 * res], axis=1)
    # Horizontal edges: y = oy + r·res for r in 0..h, one per column c.
    horiz = pad[:-1, 1:-1] != pad[1:, 1:-1]  # (h+1) × w
    r, c0, c1 = _runs(horiz)
    hz = np.stack([ox + c0 * res, oy + r * res, ox + c1 * res, oy + r * res], axis=1)
    bounds = (ox, oy, ox + w * res, oy + h * res)
    return World(np.concatenate([v, hz]), np.empty((0, 3)), name=name, bounds=bounds)


def _runs(mask: npt.NDArray[np.bool_]) -> tuple[F64, F64, F64]:
    """Runs of True along axis 1: (line index, start, end) with end exclusive."""
    lines = mask.shape[0]
    pad = np.zeros((lines, mask.shape[1] + 2), dtype=np.int8)
    pad[:, 1:-1] = mask
    d = np.diff(pad, axis=1)
    li, start = np.nonzero(d == 1)
    _, end = np.nonzero(d == -1)
    return li.astype(np.float64), start.astype(np.float64), end.astype(np.float64)
