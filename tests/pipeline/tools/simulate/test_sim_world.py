"""Worlds: TOML loading, occupancy-grid worlds, rasterising, the shipped sample worlds."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from formats.errors import ConfigError
from formats.map_types import GridSpec
from pipeline.tools.simulate import load_waypoints, load_world, world_from_occupancy
from pipeline.tools.simulate.world import World

WORLDS = Path(__file__).resolve().parents[4] / "sample_logs" / "worlds"


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "w.toml"
    p.write_text(text, encoding="utf-8")
    return p


def test_toml_world_segments_polygon_circle(tmp_path: Path) -> None:
    p = _write(
        tmp_path,
        """
name = "box"
[[segment]]
from = [0.0, 0.0]
to = [1.0, 0.5]
[[polygon]]
points = [[2, 2], [3, 2], [3, 3]]
[[circle]]
center = [5.0, 1.0]
radius = 0.25
""",
    )
    w = load_world(p)
    assert w.name == "box"
    # The polygon is closed: 3 points give 3 segments, the last back to the first.
    np.testing.assert_array_equal(
        w.segments,
        [[0, 0, 1, 0.5], [2, 2, 3, 2], [3, 2, 3, 3], [3, 3, 2, 2]],
    )
    np.testing.assert_array_equal(w.circles, [[5.0, 1.0, 0.25]])
    # No bounds given: the obstacles' bounding box, circles included.
    assert w.bounds == (0.0, 0.0, 5.25, 3.0)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[[circle]]\ncenter = [0, 0]\nradius = -1\n", r"circle\[0\]\.radius' must be in \(0, 500\] m, got -1"),
        ("[[segment]]\nfrom = [0, 0]\nto = [1]\n", r"segment\[0\]\.to' must be \[x, y\]"),
        ("name = 'x'\n", "no obstacles"),
        ("wall = 1\n", "unknown key 'wall'"),
        ("[[polygon]]\npoints = [[0, 0]]\n", r"polygon\[0\]\.points' must be an array"),
        ("bounds = [0, 0, -1, 1]\n[[circle]]\ncenter = [0, 0]\nradius = 1\n", "xmin < xmax"),
        ("[[segment\n", "invalid TOML"),
    ],
)
def test_toml_world_errors_name_file_and_key(tmp_path: Path, text: str, match: str) -> None:
    p = _write(tmp_path, text)
    with pytest.raises(ConfigError, match=match) as info:
        load_world(p)
    assert info.value.path == str(p)


def test_missing_world_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="world file not found"):
        load_world(tmp_path / "nope.toml")


def test_occupancy_world_merges_boundary_edges() -> None:
    classes = np.full((4, 5), 0, dtype=np.int8)
    classes[1:3, 1:3] = 1  # a 2×2 block
    classes[0, 4] = 1  # a single cell in the bottom-right corner
    classes[3, 0] = -1  # unknown cells are not occupied
    grid = GridSpec(origin_x=10.0, origin_y=-1.0, resolution=0.5, width=5, height=4)
    w = world_from_occupancy(classes, grid)
    segs = {tuple(np.round(s, 9)) for s in w.segments.tolist()}
    block = {
        (10.5, -0.5, 10.5, 0.5),  # left side, two edges merged
        (11.5, -0.5, 11.5, 0.5),  # right side
        (10.5, -0.5, 11.5, -0.5),  # bottom
        (10.5, 0.5, 11.5, 0.5),  # top
    }
    corner = {
        (12.0, -1.0, 12.0, -0.5),
        (12.5, -1.0, 12.5, -0.5),  # the grid border counts as non-occupied
        (12.0, -1.0, 12.5, -1.0),
        (12.0, -0.5, 12.5, -0.5),
    }
    assert segs == block | corner
    assert w.bounds == (10.0, -1.0, 12.5, 1.0)


def test_nav2_map_world_round_trip(tmp_path: Path) -> None:
    from formats.writers.nav2_map import write_nav2_map

    grid = GridSpec(0.0, 0.0, 0.1, 6, 4)
    prob = np.zeros((4, 6), np.float32)
    prob[2, 1:5] = 1.0  # a wall one cell thick along row 2
    write_nav2_map(tmp_path / "m.yaml", prob, grid)
    w = load_world(tmp_path / "m.yaml")
    assert w.name == "m"
    # The wall's outline: two long edges and two short ends.
    edge = w.segments[:, 2:] - w.segments[:, :2]
    lengths = sorted(round(float(v), 9) for v in np.hypot(edge[:, 0], edge[:, 1]))
    assert lengths == [0.1, 0.1, 0.4, 0.4]
    np.testing.assert_allclose(w.segments[:, [1, 3]].min(), 0.2)
    np.testing.assert_allclose(w.segments[:, [1, 3]].max(), 0.3)


def test_rasterize_segment_and_circle_row0_is_min_y() -> None:
    w = World(np.array([[0.0, 0.25, 1.0, 0.25]]), np.array([[0.5, 0.75, 0.11]]))
    grid = GridSpec(0.0, 0.0, 0.1, 10, 10)
    p = w.rasterize(grid)
    assert p.dtype == np.float32 and p.shape == (10, 10)
    # The segment at y = 0.25 lies in row 2 (y in [0.2, 0.3)), all 10 columns.
    np.testing.assert_array_equal(p[2], np.ones(10))
    # The disc (x 0.39…0.61, y 0.64…0.86) spans columns 3..6 and rows 6..8, but the
    # corner cells' nearest points are 0.112 m > r from the centre.
    rows, cols = np.nonzero(p)
    disc = {(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if r != 2}
    box = {(r, c) for r in (6, 7, 8) for c in (3, 4, 5, 6)}
    assert disc == box - {(6, 3), (6, 6), (8, 3), (8, 6)}
    assert float(p.sum()) == 10 + len(disc)


def _distance_to_segments(px: np.ndarray, py: np.ndarray, seg: np.ndarray) -> np.ndarray:
    ax, ay, bx, by = (seg[None, :, i] for i in range(4))
    ex, ey = bx - ax, by - ay
    t = ((px[:, None] - ax) * ex + (py[:, None] - ay) * ey) / (ex * ex + ey * ey)
    t = np.clip(t, 0, 1)
    return np.hypot(ax + t * ex - px[:, None], ay + t * ey - py[:, None]).min(axis=1)


@pytest.mark.parametrize("name", ["office", "corridor", "orchard"])
def test_shipped_worlds_waypoint_paths_stay_in_free_space(name: str) -> None:
    w = load_world(WORLDS / f"{name}.toml")
    wp = load_waypoints(WORLDS / f"{name}.waypoints.csv")
    assert w.name == name and wp.shape[1] == 2 and wp.shape[0] >= 3
    # Points every 2 cm along the path keep a robot radius (0.3 m) plus margin clear.
    s = np.linspace(0, 1, 200)
    pts = np.concatenate([a + s[:, None] * (b - a) for a, b in itertools.pairwise(wp)])
    clear = np.full(pts.shape[0], np.inf)
    if w.segments.shape[0]:
        clear = _distance_to_segments(pts[:, 0], pts[:, 1], w.segments)
    if w.circles.shape[0]:
        dc = np.hypot(
            pts[:, None, 0] - w.circles[None, :, 0], pts[:, None, 1] - w.circles[None, :, 1]
        )
        clear = np.minimum(clear, (dc - w.circles[None, :, 2]).min(axis=1))
    assert clear.min() >= 0.35
    x0, y0, x1, y1 = w.bounds
    assert (pts[:, 0] > x0).all() and (pts[:, 0] < x1).all()
    assert (pts[:, 1] > y0).all() and (pts[:, 1] < y1).all()


def test_orchard_has_round_trunks_of_paper_size() -> None:
    w = load_world(WORLDS / "orchard.toml")
    assert w.segments.shape[0] == 0 and w.circles.shape[0] == 28
    assert w.circles[:, 2].min() >= 0.1 and w.circles[:, 2].max() <= 0.2


def test_waypoint_file_errors(tmp_path: Path) -> None:
    p = tmp_path / "w.csv"
    p.write_text("x,y\n0,0\n1,abc\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="bad waypoint row 3"):
        load_waypoints(p)
    p.write_text("# only one\n1,2\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="need at least 2 waypoints, got 1"):
        load_waypoints(p)
