"""The two map layers and the final map (ALGORITHM.md §5, eqs. 11-12).

* Free layer: float32 log-odds per cell, prior ``l0 = 0`` (p0 = 0.5). For every cell of a
  scan's free-space scan ``l ← clamp(l + logit(p_free) − l0, logit(p_clamp_min),
  logit(p_clamp_max))`` (eq. 11). Since ``p_free < 0.5`` every update is strictly negative,
  so a cell is *observed* exactly when ``l ≠ 0``; no separate mask is needed. The layer
  stores the number of updates per cell and maps it through a table of the sequential
  float32 clamp (bit-identical to in-place updates; an update is an integer add over the
  scan's window).
* Occupied layer: recomputed from the feature set when a map is produced — each feature's
  2σ ellipse (cells whose centre has Mahalanobis distance ≤ 2); a feature whose ellipse
  holds no cell centre still marks the cell containing its mean. Features outside the grid
  mark nothing.
* Final map (eq. 12): ``p_occ`` inside any ellipse, else ``1 − 1/(1 + exp(l))`` where
  observed, NaN where unknown.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from pipeline.mapper.grid_raster import ellipse_spans, mean_cells, span_cells
from pipeline.mapper.kernels.attribution import empty_span_counts
from pipeline.mapper.types import F32, F64, I64, B, GridSpec


def logit(p: float) -> float:
    """log(p / (1 − p))."""
    return math.log(p / (1.0 - p))


class FreeLayer:
    """Log-odds of the free layer (eq. 11), float32, ``[row, col]`` as GridSpec.

    Every update adds the same step from the same prior, so a cell's log-odds depends only
    on how many updates it has had: the layer keeps that count per cell and maps it through
    a table of the sequential float32 clamp ``v_k = clamp(v_{k−1} + step)``, bit-identical
    to updating the log-odds in place, while an update is one integer add per cell.

    Row runs of updates may also go into :attr:`row_diff` (``+1`` at a run's first column,
    ``−1`` past its last: two adds per run, not one per cell); :attr:`counts` sums them in
    when read (integer adds: the same counts in any order).
    """

    def __init__(self, grid: GridSpec, p_free: float, p_min: float, p_max: float) -> None:
        self.grid = grid
        self._counts: npt.NDArray[np.int32] = np.zeros(grid.shape, dtype=np.int32)
        self.row_diff: npt.NDArray[np.int32] = empty_span_counts(grid.shape)
        self._diff_used = False
        self.step = np.float32(logit(p_free))  # − l0, which is 0
        self.l_min = np.float32(logit(p_min))
        self.l_max = np.float32(logit(p_max))
        self._table = _clamp_table(self.step, self.l_min, self.l_max)

    @property
    def counts(self) -> npt.NDArray[np.int32]:
        """Updates per cell, :attr:`row_diff`'s summed in (and cleared)."""
        if self._diff_used:
            self._counts += np.cumsum(self.row_diff[:, :-1], axis=1, dtype=np.int32)
            self.row_diff[:] = 0
            self._diff_used = False
        return self._counts

    def diff_for_rows(self) -> npt.NDArray[np.int32]:
        """:attr:`row_diff`, to add row runs to (summed in when :attr:`counts` is read)."""
        self._diff_used = True
        return self.row_diff

    def update(self, cells: I64) -> None:
        """Apply eq. 11 once to each flat cell index in ``cells`` (must be unique)."""
        self.counts.reshape(-1)[cells] += 1

    def update_window(self, row0: int, col0: int, mask: B) -> None:
        """Apply eq. 11 once to every True cell of ``mask`` placed at ``(row0, col0)``."""
        h, w = mask.shape
        self.counts[row0 : row0 + h, col0 : col0 + w] += mask

    @property
    def logodds(self) -> F32:
        """The log-odds per cell (a new array)."""
        k = self._table.shape[0] - 1
        out: F32 = self._table[np.minimum(self.counts, k)]
        return out

    @property
    def observed(self) -> B:
        return self.logodds != 0


def _clamp_table(step: np.float32, l_min: np.float32, l_max: np.float32) -> F32:
    """``[v_0 = 0, v_1, …, v_K]`` with ``v_k = clip(v_{k−1} + step, l_min, l_max)`` in float32,
    up to the first fixed point (the clamp, or float32 absorbing the step)."""
    vals = [np.float32(0.0)]
    while True:
        v = np.clip(vals[-1] + step, l_min, l_max).astype(np.float32)
        if v == vals[-1] or len(vals) > 1_000_000:
            break
        vals.append(v)
    return np.array(vals, dtype=np.float32)


_RASTER_BLOCK = 2048  # features rasterised at once by occupied_layer


def occupied_layer(mean: F64, cov: F64, grid: GridSpec) -> B:
    """Cells inside any feature's 2σ ellipse, plus each in-grid feature's mean cell."""
    occ = np.zeros(grid.shape, dtype=np.bool_)
    if mean.shape[0] == 0:
        return occ
    # In blocks of features: the cells of every ellipse at once would make temporaries
    # that grow with the feature count (tens of MB for tens of thousands of features).
    for a in range(0, mean.shape[0], _RASTER_BLOCK):
        mb, cb = mean[a : a + _RASTER_BLOCK], cov[a : a + _RASTER_BLOCK]
        spans = ellipse_spans(mb[:, 0], mb[:, 1], cb[:, 0], cb[:, 1], cb[:, 2], 2.0, grid)
        _, row, col = span_cells(spans)
        occ[row, col] = True
    r, c, inside = mean_cells(mean[:, 0], mean[:, 1], grid)
    occ[r[inside], c[inside]] = True
    return occ


def final_probability(occupied: B, logodds: F32, p_occ: float) -> F32:
    """Eq. 12: ``p_occ`` in occupied cells, else from the free log-odds, NaN if unknown."""
    with np.errstate(over="ignore"):
        p_free = 1.0 - 1.0 / (1.0 + np.exp(logodds.astype(np.float64)))
    p = np.where(logodds != 0, p_free, np.nan)
    p = np.where(occupied, p_occ, p)
    return p.astype(np.float32)
