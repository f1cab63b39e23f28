"""benchmarks.octomap_baseline: the OctoMap anchor read back as OctoMap's own search reads it."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # benchmarks/ is not an installed package
    sys.path.insert(0, str(ROOT))

from benchmarks import octomap_baseline as ob  # noqa: E402
from formats.map_types import GridSpec  # noqa: E402

octomap = pytest.importorskip("octomap")
RES = 0.05


def _tree_with_leaves_of_several_sizes() -> object:
    """Single voxels far from the origin (float32 centres like −31.975) and pruned leaves of
    2, 4 and 8 voxels (blocks set to one value merge into one leaf)."""
    tree = octomap.OcTree(RES)
    rng = np.random.default_rng(3)
    for x, y in rng.uniform(-32.0, -30.0, size=(300, 2)):
        tree.updateNode(np.array([x, y, 0.01]), bool(rng.integers(2)))
    for n, (i0, j0) in ((2, (40, 8)), (4, (16, 24)), (8, (-64, -40))):
        for i in range(i0, i0 + n):
            for j in range(j0, j0 + n):
                for k in range(n):
                    tree.updateNode(np.array([(i + 0.5) * RES, (j + 0.5) * RES,
                                              (k + 0.5) * RES]), True)
    return tree


@pytest.mark.parametrize("offset", [0.0, 0.02, RES / 2])
def test_leaves_on_grid_equals_search_at_every_cell_centre(offset: float) -> None:
    tree = _tree_with_leaves_of_several_sizes()
    sizes = {round(leaf.getSize() / RES) for leaf in tree.begin_leafs()}
    assert {1, 2, 4, 8} <= sizes  # the tree really has leaves of several sizes
    grid = GridSpec(origin_x=-32.5 + offset, origin_y=-32.5 + offset, resolution=RES,
                    width=700, height=700)
    got = ob.leaves_on_grid(tree, grid)
    want = ob.searched_on_grid(tree, grid)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    known = ~np.isnan(want)
    assert known.sum() > 300
    assert np.array_equal(got[known], want[known])


def test_leaves_above_the_z0_slice_are_not_read() -> None:
    tree = octomap.OcTree(RES)
    tree.updateNode(np.array([0.01, 0.01, 0.30]), True)  # a voxel at z = 0.30 m only
    grid = GridSpec(origin_x=-0.5, origin_y=-0.5, resolution=RES, width=20, height=20)
    assert np.isnan(ob.leaves_on_grid(tree, grid)).all()
