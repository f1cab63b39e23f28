"""map.png: size, colours of known cells, overlays, crop, axes and legend, determinism."""

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
    MapFrame,
    crop_to_observed,
    render_map,
    render_map_with_frame,
    write_map_png,
)

# 20 × 10 cells of 0.1 m: the map spans x ∈ [0, 2), y ∈ [0, 1)
GRID = GridSpec(origin_x=0.0, origin_y=0.0, resolution=0.1, width=20, height=10)


def _prob() -> np.ndarray:
    prob = np.full(GRID.shape, np.nan, dtype=np.float32)
    prob[:, :10] = 0.0  # left half free
    prob[0, 0] = 1.0  # occupied at min y, min x → bottom-left of the picture
    prob[9, 19] = 0.5  # top-right, half
    return prob


def _px(frame: MapFrame, x: float, y: float) -> tuple[int, int]:
    u, v = frame.to_px(np.array([x]), np.array([y]))
    return int(u[0]), int(v[0])


def _cell_centre_px(frame: MapFrame, row: int, col: int) -> tuple[int, int]:
    """Image (u, v) of a cell centre: row 0 (min y) is drawn at the bottom."""
    g = frame.grid
    return _px(frame, g.origin_x + (col + 0.5) * g.resolution, g.origin_y + (row + 0.5) * g.resolution)


def test_size_and_cell_colours(tmp_path: Path) -> None:
    empty = make_features([], [], [])
    snap = make_snapshot(GRID, _prob(), empty)
    write_map_png(tmp_path / "map.png", snap, trajectory_xy=None, features=None)
    img = Image.open(tmp_path / "map.png")
    assert img.mode == "RGB"
    expected, frame, (map_w, map_h) = render_map_with_frame(
        snap, trajectory_xy=None, features=None, crop=False)
    assert np.array_equal(np.asarray(img), np.asarray(expected))  # crop: every cell has evidence
    assert (map_w, map_h) == (20 * 30, 10 * 30)  # 30 px per cell: ceil(600 / 20)
    px = img.load()
    assert px is not None
    assert px[_cell_centre_px(frame, 0, 0)] == (0, 0, 0)  # occupied: black
    assert px[_cell_centre_px(frame, 5, 5)] == (255, 255, 255)  # free: white
    assert px[_cell_centre_px(frame, 3, 15)] == UNKNOWN_RGB  # unknown
    assert px[_cell_centre_px(frame, 9, 19)] == (128, 128, 128)  # p = 0.5 shaded
    # row flip: the occupied cell's block is at the bottom-left of the map area
    assert px[frame.left + 1, frame.top + map_h - 2] == (0, 0, 0)
    assert px[frame.left + 3, frame.top + 3] == (255, 255, 255)


def test_long_side_limits() -> None:
    tiny = GridSpec(0.0, 0.0, 0.05, 3, 2)
    _img, _frame, (map_w, _h) = render_map_with_frame(
        make_snapshot(tiny, np.zeros(tiny.shape), make_features([], [], [])),
        trajectory_xy=None, features=None,
    )  # fmt: skip
    assert map_w == 3 * 200 >= MIN_SIDE_PX
    big = GridSpec(0.0, 0.0, 0.05, 5000, 30)
    prob = np.zeros(big.shape, dtype=np.float32)
    prob[10, 4321] = 1.0  # one thin obstacle must survive the reduction
    img, frame, (map_w, map_h) = render_map_with_frame(
        make_snapshot(big, prob, make_features([], [], [])), trajectory_xy=None, features=None
    )
    assert map_w == 1667 <= MAX_SIDE_PX  # 3 cells per pixel: ceil(5000 / 3)
    area = np.asarray(img)[frame.top : frame.top + map_h, frame.left : frame.left + map_w, 0]
    # block-max keeps the single obstacle: cell (10, 4321) → block (3, 1440) → image row 6
    assert np.argwhere(area == 0).tolist() == [[6, 1440]]


def test_cropped_to_the_observed_area_plus_a_margin() -> None:
    grid = GridSpec(-10.0, -10.0, 0.1, 400, 300)  # 40 m × 30 m
    prob = np.full(grid.shape, np.nan, dtype=np.float32)
    prob[100:120, 150:160] = 0.0  # observed: y ∈ [0, 2), x ∈ [5, 6)
    traj = np.array([[5.5, 0.5], [7.0, 1.0]])
    sub, sub_grid = crop_to_observed(prob, grid, traj)
    # Observed cells and trajectory, grown by CROP_MARGIN_M = 1 m = 10 cells on each side.
    assert (sub_grid.origin_x, sub_grid.origin_y) == (4.0, -1.0)
    assert (sub_grid.width, sub_grid.height) == (41, 40)  # x ∈ [4, 8.1), y ∈ [-1, 3)
    assert np.array_equal(sub, prob[90:130, 140:181], equal_nan=True)
    assert crop_to_observed(np.full((3, 3), np.nan, np.float32), GridSpec(0, 0, 1, 3, 3), None)[1] \
        == GridSpec(0, 0, 1, 3, 3)  # nothing observed: the whole grid
    _img, frame, _size = render_map_with_frame(
        make_snapshot(grid, prob, make_features([], [], [])), trajectory_xy=traj, features=None)
    assert frame.grid == sub_grid


def test_metre_ticks_and_legend() -> None:
    feats = make_features(x=[1.5], y=[0.5], cov=[(0.01, 0.0, 0.0025)])
    img, frame, (_map_w, map_h) = render_map_with_frame(
        make_snapshot(GRID, _prob(), feats), trajectory_xy=np.array([[0.1, 0.1], [1.0, 0.9]]),
        features=feats, crop=False)
    arr = np.asarray(img)
    # A tick mark under the map every 0.5 m (about 8 ticks over the 2 m span): x = 1.5 m.
    u, _v = _px(frame, 1.5, 0.0)
    below = arr[frame.top + map_h + 1 : frame.top + map_h + 4, u]
    assert (below == 0).all()
    # The legend shows a swatch of each map colour, the trajectory and the ellipse colour.
    legend = arr[frame.top + map_h + 30 :]
    colours = {tuple(c) for c in legend.reshape(-1, 3).tolist()}
    assert {UNKNOWN_RGB, TRAJECTORY_RGB, ELLIPSE_RGB} <= colours


def test_trajectory_and_ellipses_drawn(tmp_path: Path) -> None:
    feats = make_features(x=[1.5], y=[0.5], cov=[(0.01, 0.0, 0.0025)])  # 2σ: 0.2 m × 0.1 m
    traj = np.array([[0.05, 0.05], [0.95, 0.95], [np.nan, np.nan], [1.2, 0.2], [1.9, 0.2]])
    snap = make_snapshot(GRID, np.zeros(GRID.shape), feats)
    img, frame, _size = render_map_with_frame(snap, trajectory_xy=traj, features=feats, title="demo",
                                              crop=False)
    arr = np.asarray(img)
    # ellipse: major axis along x, 2σ = 0.2 m = 60 px from the centre
    cu, cv = _px(frame, 1.5, 0.5)
    assert tuple(arr[cv, cu + 60]) == ELLIPSE_RGB or tuple(arr[cv, cu + 59]) == ELLIPSE_RGB
    assert tuple(arr[cv - 30, cu]) == ELLIPSE_RGB or tuple(arr[cv - 29, cu]) == ELLIPSE_RGB
    iu, iv = _px(frame, 1.53, 0.52)  # inside, off the 0.5 m grid lines
    assert tuple(arr[iv, iu]) == (255, 255, 255)  # outline only
    # trajectory: diagonal from (0.05, 0.05) to (0.95, 0.95) passes (0.5, 0.5)
    u, v = _px(frame, 0.5, 0.5)
    assert tuple(arr[v, u]) == TRAJECTORY_RGB
    # the NaN gap is not bridged: nothing at the midpoint of (0.95,0.95)–(1.2,0.2)
    gu, gv = _px(frame, 1.075, 0.575)
    assert tuple(arr[gv, gu]) == (255, 255, 255)


def test_ellipse_orientation_follows_covariance() -> None:
    # 45° major axis: [[0.02, 0.01], [0.01, 0.02]] → σ_major² = 0.03
    feats = make_features(x=[1.0], y=[0.5], cov=[(0.02, 0.01, 0.02)])
    img, frame, _size = render_map_with_frame(
        make_snapshot(GRID, np.zeros(GRID.shape), feats), trajectory_xy=None, features=feats,
        crop=False,
    )
    arr = np.asarray(img)
    scale = 30
    cu, cv = _px(frame, 1.0, 0.5)
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


def test_tick_labels_are_plain_text_the_default_font_has() -> None:
    from formats.writers.map_png import _tick_label

    assert [_tick_label(v, 5.0) for v in (-10.0, -0.0, 5.0)] == ["-10", "0", "5"]
    assert [_tick_label(v, 0.5) for v in (-0.5, 1.0)] == ["-0.5", "1.0"]
