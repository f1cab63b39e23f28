"""Walls as one-cell lines, matched one to one: the cell correspondence evaluate scores.

The Berkeley boundary benchmark's rule (Martin, Fowlkes & Malik 2004, "Learning to detect
natural image boundaries using local brightness, color, and texture cues", IEEE PAMI 26(5);
its ``correspondPixels``), on occupancy grids:

* **Thinning** (:func:`thin`). A wall drawn k cells thick becomes its one-cell centre
  line: Guo & Hall's parallel thinning (1989, "Parallel thinning with two-subiteration
  algorithms", CACM 32(3), algorithm A1; MATLAB's ``bwmorph(..., 'thin', Inf)``, the
  benchmark's own thinning). It keeps connectivity, end points and holes: a one-cell line
  stays as it is, a k-cell-thick bar keeps its length less about k/2 cells at each end, a
  ring stays a ring; it is idempotent.
* **Inside solids** (:func:`interior`). A ground truth models solid things (a simulated
  trunk is a filled disc); a range sensor sees only their surfaces. A truth cell whose 8
  neighbours are all true walls is inside a solid: no sensor observes it, so it is taken
  out of the truth *and* of the map before thinning. A solid then becomes its rim in both,
  whether the map drew it filled or as an outline; a wall up to two cells thick has no
  inside and is untouched.
* **Matching** (:func:`match`). A map cell and a truth cell may correspond when their
  centres are within the tolerance; each cell corresponds to at most one other. The
  correspondence is a maximum bipartite matching (Hopcroft-Karp,
  ``scipy.sparse.csgraph.maximum_bipartite_matching``), so a second line drawn along a
  wall that is already matched stays unmatched and costs precision, and one map cell
  cannot account for several truth cells. Deterministic: the graph is built in row-major
  cell order.

Scored this way, how thick a wall is drawn does not change its score (the map is thinned
first), and surplus parallel lines cost precision (they find no partner); the truth
scored as a map scores 1.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from formats.arrays import B

__all__ = ["interior", "match", "thin"]

# Neighbours x1..x8 of a cell, counter-clockwise from +column: (row offset, column offset).
_RING = ((0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1), (-1, 0), (-1, 1))


def _deletable(code: int, first: bool) -> bool:
    """Guo-Hall's conditions G1, G2 and G3 (first subiteration) or G3' (second) for a cell
    whose eight neighbours x1..x8 are the bits of ``code`` (x1 the lowest)."""
    x = [bool(code >> i & 1) for i in range(8)]
    x1, x2, x3, x4, x5, x6, x7, x8 = x
    # G1: exactly one 4-connected run of neighbours (the crossing number X_H).
    crossings = sum(not x[2 * i] and (x[2 * i + 1] or x[(2 * i + 2) % 8]) for i in range(4))
    # G2: 2 <= min(n1, n2) <= 3 (not an end point, not interior).
    n1 = sum(x[2 * k] or x[2 * k + 1] for k in range(4))
    n2 = sum(x[2 * k + 1] or x[(2 * k + 2) % 8] for k in range(4))
    # G3 (G3'): not ((x2 or x3 or not x8) and x1): deletes south-east (north-west) border
    # cells first, so a two-cell-thick line loses one side only.
    g3 = not ((x2 or x3 or not x8) and x1) if first else not ((x6 or x7 or not x4) and x5)
    return crossings == 1 and 2 <= min(n1, n2) <= 3 and g3


_LUTS = tuple(np.array([_deletable(c, first) for c in range(256)], dtype=bool)
              for first in (True, False))


def _codes(mask: B) -> npt.NDArray[np.uint8]:
    """Each cell's neighbourhood as an 8-bit code (x1 the lowest bit); outside = empty."""
    padded = np.pad(mask, 1)
    h, w = mask.shape
    code = np.zeros(mask.shape, dtype=np.uint8)
    for bit, (dr, dc) in enumerate(_RING):
        code |= padded[1 + dr:1 + dr + h, 1 + dc:1 + dc + w].astype(np.uint8) << bit
    return code


def thin(mask: B) -> B:
    """``mask`` thinned to one-cell lines (Guo-Hall A1, to convergence); a new array."""
    out = np.zeros(mask.shape, dtype=bool)
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return out
    box = (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1))
    cur = mask[box].copy()
    changed = True
    while changed:
        changed = False
        for lut in _LUTS:
            gone = cur & lut[_codes(cur)]
            if gone.any():
                cur &= ~gone
                changed = True
    out[box] = cur
    return out


def interior(mask: B) -> B:
    """The cells of ``mask`` whose 8 neighbours are all in it (outside the grid is not):
    the inside of a solid; none in a wall up to two cells thick."""
    return np.asarray(mask & (_codes(mask) == 255), dtype=bool)


def _offsets(tolerance_m: float, resolution: float) -> list[tuple[int, int]]:
    """Cell offsets whose centre distance is within the tolerance (rounding allowed, so
    two cells at 0.05 m are within 0.10 m), in row-major order."""
    k = math.floor(tolerance_m / resolution + 1e-9)
    limit = tolerance_m * (1.0 + 1e-9) + 1e-12
    return [(dr, dc) for dr in range(-k, k + 1) for dc in range(-k, k + 1)
            if math.hypot(dr, dc) * resolution <= limit]


def match(a: B, b: B, tolerance_m: float, resolution: float) -> tuple[B, B]:
    """The cells of ``a`` and of ``b`` (masks on one grid of cell size ``resolution``, m)
    that a maximum one-to-one matching pairs, each pair within ``tolerance_m``."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import maximum_bipartite_matching

    ra, ca = np.nonzero(a)
    rb, cb = np.nonzero(b)
    matched_a = np.zeros(a.shape, dtype=bool)
    matched_b = np.zeros(b.shape, dtype=bool)
    if ra.size == 0 or rb.size == 0:
        return matched_a, matched_b
    id_b = np.full(b.shape, -1, dtype=np.int64)
    id_b[rb, cb] = np.arange(rb.size)
    h, w = a.shape
    src, dst = [], []
    for dr, dc in _offsets(tolerance_m, resolution):
        r, c = ra + dr, ca + dc
        ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        j = np.full(ra.size, -1, dtype=np.int64)
        j[ok] = id_b[r[ok], c[ok]]
        hit = np.nonzero(j >= 0)[0]
        src.append(hit)
        dst.append(j[hit])
    i_all, j_all = np.concatenate(src), np.concatenate(dst)
    order = np.lexsort((j_all, i_all))
    graph = csr_matrix((np.ones(order.size, dtype=np.int8), (i_all[order], j_all[order])),
                       shape=(ra.size, rb.size))
    partner = np.asarray(maximum_bipartite_matching(graph, perm_type="column"))
    paired = partner >= 0
    matched_a[ra[paired], ca[paired]] = True
    matched_b[rb[partner[paired]], cb[partner[paired]]] = True
    return matched_a, matched_b
