"""wall_matching: Guo-Hall thinning, insides of solids, one-to-one cell matching."""

from __future__ import annotations

import numpy as np

from pipeline.tools.wall_matching import interior, match, thin


def _bar(rows: slice, cols: slice, shape: tuple[int, int] = (9, 16)) -> np.ndarray:
    m = np.zeros(shape, dtype=bool)
    m[rows, cols] = True
    return m


def test_a_thick_bar_thins_to_one_line_of_cells() -> None:
    for thickness in (1, 2, 3, 4):
        out = thin(_bar(slice(2, 2 + thickness), slice(1, 15)))
        rows = np.unique(np.nonzero(out)[0])
        assert rows.size == 1  # one line, on one row of the bar
        assert 2 <= rows[0] < 2 + thickness
        # the line spans the bar, its ends shortened by at most half the thickness each
        assert out.sum() >= 14 - thickness


def test_thinning_keeps_lines_rings_and_isolated_cells_and_is_idempotent() -> None:
    line = _bar(slice(4, 5), slice(1, 15))
    np.testing.assert_array_equal(thin(line), line)
    dots = np.zeros((5, 5), dtype=bool)
    dots[1, 1] = dots[3, 3] = True
    np.testing.assert_array_equal(thin(dots), dots)
    ring = _bar(slice(1, 8), slice(2, 9))
    ring[3:6, 4:7] = False  # a square band two cells thick around a 3×3 hole
    out = thin(ring)
    assert not out[3:6, 4:7].any() and out.sum() < ring.sum()
    # still a closed loop: the hole stays enclosed (not connected to the outside)
    from scipy.ndimage import label

    _, n = label(~out)
    assert n == 2
    np.testing.assert_array_equal(thin(out), out)


def test_a_solid_disc_less_its_inside_thins_to_its_rim() -> None:
    yy, xx = np.mgrid[:15, :15]
    disc = (yy - 7) ** 2 + (xx - 7) ** 2 <= 16
    inside = interior(disc)
    # inside: every cell whose 8 neighbours are all in the disc (a 3×3 core among them)
    assert inside[6:9, 6:9].all() and not inside[7, 3] and not inside[3, 7]
    assert not interior(_bar(slice(2, 4), slice(1, 15))).any()  # a 2-cell wall has none
    walls = thin(disc & ~inside)
    # a closed ring round the disc (circumference 2π·4 ≈ 25 cell sizes; diagonal steps
    # are √2 long), not its centre, which thinning the filled disc would give
    from scipy.ndimage import label

    assert label(~walls)[1] == 2 and not walls[7, 7] and 16 <= walls.sum() <= 25
    assert thin(disc).sum() <= 3


def test_matching_is_one_to_one_and_maximum() -> None:
    # Row: true, run, true, run (1 m cells, tolerance 1 m). The first run cell could take
    # either true cell; a maximum matching gives it the first, the second run cell the other.
    a = np.array([[False, True, False, True]])
    b = np.array([[True, False, True, False]])
    ma, mb = match(a, b, 1.0, 1.0)
    np.testing.assert_array_equal(ma, a)
    np.testing.assert_array_equal(mb, b)
    # Three run cells around one true cell: one pair.
    a = np.array([[True, True, True]])
    b = np.array([[False, True, False]])
    ma, mb = match(a, b, 1.0, 1.0)
    assert ma.sum() == 1 and mb.sum() == 1
    # Diagonal neighbours (1.414 m apart) are beyond a 1 m tolerance, within 1.5 m.
    a = np.array([[True, False], [False, False]])
    b = np.array([[False, False], [False, True]])
    assert match(a, b, 1.0, 1.0)[0].sum() == 0
    assert match(a, b, 1.5, 1.0)[0].sum() == 1
    # Two cells at 0.05 m lie within 0.10 m despite rounding; nothing to match: empty masks.
    a = np.array([[True, False, False]])
    b = np.array([[False, False, True]])
    assert match(a, b, 0.10, 0.05)[1].sum() == 1
    assert match(a, np.zeros_like(a), 0.10, 0.05)[0].sum() == 0
