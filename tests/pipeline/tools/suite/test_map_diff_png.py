"""The diff picture: counts and colours of the changed cells, grids that differ, the path."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

from formats.map_types import GridSpec
from formats.writers.map_diff_png import (
    GONE_RGB,
    NEW_RGB,
    map_diff,
    render_map_diff,
    write_map_diff_png,
)
from formats.writers.map_png import TRAJECTORY_RGB
from formats.writers.nav2_map import load_nav2_map, write_nav2_map


def room(grid: GridSpec) -> np.ndarray:
    """Free inside, a wall row at y index 10 (probability 0.9), unknown elsewhere."""
    p = np.full(grid.shape, np.nan, dtype=np.float32)
    p[5:30, 5:35] = 0.05
    p[10, 5:35] = 0.9
    return p


def write(path: Path, grid: GridSpec, prob: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_nav2_map(path.with_suffix(".yaml"), prob, grid)
    return path.with_suffix(".yaml")


def colour_count(image: Image.Image, rgb: tuple[int, int, int]) -> int:
    a = np.asarray(image)
    return int(np.all(a == np.array(rgb, dtype=np.uint8), axis=-1).sum())


def test_counts_and_colours(tmp_path: Path) -> None:
    grid = GridSpec(-1.0, -1.0, 0.1, 40, 35)
    gold = room(grid)
    cur = gold.copy()
    cur[10, 5:15] = 0.05  # 10 wall cells gone
    cur[20, 8:14] = 0.9  # 6 new wall cells
    g = write(tmp_path / "golden" / "map", grid, gold)
    c = write(tmp_path / "run" / "map", grid, cur)
    diff = map_diff(load_nav2_map(g), load_nav2_map(c))
    assert int(diff.new_occupied.sum()) == 6 and int(diff.no_longer_occupied.sum()) == 10
    assert diff.new_occupied[20, 8:14].all() and diff.no_longer_occupied[10, 5:15].all()
    xy = np.array([[0.0, 0.5], [2.0, 0.5], [2.0, 1.5]])
    png = tmp_path / "office.png"
    write_map_diff_png(png, g, c, title="office")
    image = Image.open(io.BytesIO(png.read_bytes())).convert("RGB")
    # The map is drawn at ≥ 600 px: each cell is a block of pixels of its colour.
    block = (image.width - 100) // 40
    assert colour_count(image, NEW_RGB) >= 6 * block * block
    assert colour_count(image, GONE_RGB) >= 10 * block * block
    with_path = render_map_diff(diff, xy, "office")
    assert colour_count(with_path, TRAJECTORY_RGB) > colour_count(image, TRAJECTORY_RGB) + 100
    again = tmp_path / "again.png"
    write_map_diff_png(again, g, c, title="office")
    assert again.read_bytes() == png.read_bytes()  # deterministic


def test_grids_that_differ_are_laid_on_one(tmp_path: Path) -> None:
    """The new map reaches 1 m further in x and starts 0.5 m lower: the same walls are no
    change; the cells only the new map has are compared against unknown."""
    g_grid = GridSpec(-1.0, -1.0, 0.1, 40, 35)
    c_grid = GridSpec(-1.0, -1.5, 0.1, 50, 40)
    gold = room(g_grid)
    cur = np.full(c_grid.shape, np.nan, dtype=np.float32)
    cur[5:40, :40] = gold  # same world place: rows shifted by 5
    cur[20, 42:46] = 0.9  # 4 new wall cells outside the golden map
    diff = map_diff(load_nav2_map(write(tmp_path / "g" / "map", g_grid, gold)),
                    load_nav2_map(write(tmp_path / "c" / "map", c_grid, cur)))
    assert diff.grid.shape == (40, 50)
    assert (diff.grid.origin_x, diff.grid.origin_y) == (-1.0, -1.5)
    assert int(diff.new_occupied.sum()) == 4 and int(diff.no_longer_occupied.sum()) == 0
