"""map.png: size, colours of known cells, overlays, determinism."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from writers_helpers import make_features, make_snapshot

from formats.map_types import FeatureTable, GridSpec
from formats.writers.map_png import (
    ELLIPSE_RGB,
    MAX_SIDE_PX,
    MIN_SIDE_PX,
    TRAJECTORY_RGB,
    UNKNOWN_RGB,
    render_map,
    write_map_png,
)

# 20 × 10 cells of 0.1 m: the map spans x ∈ [0, 2), y ∈ [0, 1)
GRID = GridSpec(origin_x=0.0, origin_y=0.0, resolution=0.1, width=20, height=10)
MARGIN = 8  # px, map_png._MARGIN


def _prob() -> np.ndarray:
    prob = np.full(GRID.shape, np.nan, dtype=np.float32)
    prob[:, :10] = 0.0  # left half free
    prob[0, 0] = 1.0  # occupied at min y, min x → bottom-left of the picture
    prob[9, 19] = 0.5  # top-right, half
    return prob


def _cell_centre_px(row: int, col: int, scale: int, top: int = MARGIN) -> tuple[int, int]:
    """Image (u, v) of a cell centre: row 0 (min y) is drawn at the bottom."""
    u = MARGIN + col * scale + scale // 2
    v = top + (GRID.height - 1 - row) * scale + scale // 2
    return u, v


def test_size_and_cell_colours(tmp_path: Path) -> None:
    empty = make_features([], [], [])
    write_map_png(
        tmp_path / "map.png", make_snapshot(GRID, _prob(), empty), trajectory_xy=None,
        features=None,
    )  # fmt: skip
    img = Image.open(tmp_path / "map.png")
    assert img.mode == "RGB"
    scale = 30  # ceil(600 / 20)
    assert img.size == (20 * scale + 2 * MARGIN, 10 * scale + 2 * MARGIN + 44)
    px = img.load()
    assert px is not None
    assert px[_cell_centre_px(0, 0, scale)] == (0, 0, 0)  # occupied: black
    assert px[_cell_centre_px(5, 5, scale)] == (255, 255, 255)  # free: white
    assert px[_cell_centre_px(3, 15, scale)] == UNKNOWN_RGB  # unknown
    assert px[_cell_centre_px(9, 19, scale)] == (128, 128, 128)  # p = 0.5 shaded
    # row flip: the occupied cell's block is at the bottom-left of the map area
    assert px[MARGIN + 1, MARGIN + 10 * scale - 2] == (0, 0, 0)
    assert px[MARGIN + 1, MARGIN + 1] == (255, 255, 255)


def test_long_side_limits() -> None:
    tiny = GridSpec(0.0, 0.0, 0.05, 3, 2)
    img = render_map(
        make_snapshot(tiny, np.zeros(tiny.shape), make_features([], [], [])),
        trajectory_xy=None, features=None,
    )  # fmt: skip
    assert img.size[0] - 2 * MARGIN == 3 * 200 >= MIN_SIDE_PX
    big = GridSpec(0.0, 0.0, 0.05, 5000, 30)
    prob = np.zeros(big.shape, dtype=np.float32)
    prob[10, 4321] = 1.0  # one thin obstacle must survive the reduction
    img = render_map(
        make_snapshot(big, prob, make_features([], [], [])), trajectory_xy=None, features=None
    )
    map_w = img.size[0] - 2 * MARGIN
    assert map_w == 1667 <= MAX_SIDE_PX  # 3 cells per pixel: ceil(5000 / 3)
    area = np.asarray(img)[MARGIN : MARGIN + 10, MARGIN : MARGIN + map_w, 0]
    # block-max keeps the single obstacle: cell (10, 4321) → block (3, 1440) → image row 6
    assert np.argwhere(area == 0).tolist() == [[6, 1440]]


def test_trajectory_and_ellipses_drawn(tmp_path: Path) -> None:
    feats = make_features(x=[1.5], y=[0.5], cov=[(0.01, 0.0, 0.0025)])  # 2σ: 0.2 m × 0.1 m
    traj = np.array([[0.05, 0.05], [0.95, 0.95], [np.nan, np.nan], [1.2, 0.2], [1.9, 0.2]])
    snap = make_snapshot(GRID, np.zeros(GRID.shape), feats)
    img = render_map(snap, trajectory_xy=traj, features=feats, title="demo")
    arr = np.asarray(img)
    top = MARGIN + 24  # title strip
    scale = 30
    # ellipse: major axis along x, 2σ = 0.2 m = 2 cells = 60 px from the centre
    cu, cv = MARGIN + 15 * scale, top + 5 * scale
    assert tuple(arr[cv, cu + 60]) == ELLIPSE_RGB or tuple(arr[cv, cu + 59]) == ELLIPSE_RGB
    assert tuple(arr[cv - 30, cu]) == ELLIPSE_RGB or tuple(arr[cv - 29, cu]) == ELLIPSE_RGB
    assert tuple(arr[cv, cu]) == (255, 255, 255)  # outline only
    # trajectory: diagonal from (0.05, 0.05) to (0.95, 0.95) passes (0.5, 0.5)
    u, v = MARGIN + 5 * scale, top + 5 * scale
    assert tuple(arr[v, u]) == TRAJECTORY_RGB
    # the NaN gap is not bridged: nothing at the midpoint of (0.95,0.95)–(1.2,0.2)
    gu, gv = MARGIN + round(10.75 * scale), top + round((10 - 5.75) * scale)
    assert tuple(arr[gv, gu]) == (255, 255, 255)


def test_ellipse_orientation_follows_covariance() -> None:
    # 45° major axis: [[0.02, 0.01], [0.01, 0.02]] → σ_major² = 0.03
    feats = make_features(x=[1.0], y=[0.5], cov=[(0.02, 0.01, 0.02)])
    img = render_map(
        make_snapshot(GRID, np.zeros(GRID.shape), feats), trajectory_xy=None, features=feats
    )
    arr = np.asarray(img)
    scale = 30
    cu, cv = MARGIN + 10 * scale, MARGIN + 5 * scale
    reach = 2 * np.sqrt(0.03) / 0.1 * scale / np.sqrt(2)  # px along each image axis
    along = [tuple(arr[cv - round(reach) + d, cu + round(reach) + e])
             for d in (-1, 0, 1) for e in (-1, 0, 1)]  # fmt: skip
    assert ELLIPSE_RGB in along  # up-right in the image = +x, +y in the world
    assert tuple(arr[cv + round(reach), cu + round(reach)]) != ELLIPSE_RGB


def test_bytes_deterministic_and_no_time_chunks(tmp_path: Path, features: FeatureTable) -> None:
    snap = make_snapshot(GRID, _prob(), features)
    traj = np.array([[0.0, 0.0], [1.0, 0.5]])
    for name in ("a.png", "b.png"):
        write_map_png(tmp_path / name, snap, trajectory_xy=traj, features=features, title="t")
    data = (tmp_path / "a.png").read_bytes()
    assert data == (tmp_path / "b.png").read_bytes()
    assert b"tIME" not in data and b"tEXt" not in data


def test_bad_trajectory_shape_refused(features: FeatureTable) -> None:
    with pytest.raises(ValueError, match=r"trajectory_xy must have shape \(N, 2\)"):
        render_map(make_snapshot(GRID, _prob(), features), trajectory_xy=np.zeros(5), features=None)
