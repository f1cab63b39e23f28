"""The andersone mapper's per-scan loop (ALGORITHM.md §6 order), compiled.

For each scan of a group: (1) merge its reading features (eqs. 5-8), (2) correct the
features its free-space scan touches (§4). What does not depend on the map state is
prepared for the whole group beforehand (:mod:`pipeline.mapper.andersone`): reading classes
and features, and the scans' free-space scans (§3) with the free layer's update (eq. 11),
:mod:`.free_unions`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pipeline.mapper.kernels.correction import CELLS_FREED, CREATED, MERGED, correct_features
from pipeline.mapper.kernels.features import (
    FeatureArrays,
    compact_if_half_dead,
    merge_readings,
)
from pipeline.mapper.kernels.free_unions import FreeUnions, union_of


@njit(cache=True, nogil=True)
def integrate_scans(fa: FeatureArrays, feat_mean: np.ndarray, feat_cov: np.ndarray,
                    feat_t: np.ndarray, feat_cut: np.ndarray, unions: FreeUnions, gx: float,
                    gy: float, res: float, width: int, height: int, match_distance: float,
                    correction: bool, pcg: np.ndarray, n_particles: int,
                    keep_n: float, protect_times: int, floor2: float, split_guard: bool,
                    refit_cells: bool, counters: np.ndarray) -> None:
    """Integrate scans ``k`` = 0.. ``len(feat_cut) − 2``: features ``feat_cut[k]:feat_cut[k+1]``,
    free-space scan ``union_of(unions, k)``; the feature store, the particles' PCG64 state
    ``pcg`` (:mod:`.normals`) and ``counters`` (correction.CREATED..CELLS_FREED) are
    updated in place (the free layer is not)."""
    for k in range(feat_cut.shape[0] - 1):
        created, merged = merge_readings(fa, feat_mean, feat_cov, feat_t, feat_cut[k],
                                         feat_cut[k + 1], match_distance)
        counters[CREATED] += created
        counters[MERGED] += merged
        row0, col0, col1, starts, c0s, c1s, count = union_of(unions, k)
        if count == 0:
            continue
        if correction:
            correct_features(fa, row0, col0, col1, starts, c0s, c1s, gx, gy, res, width, height,
                             pcg, n_particles, keep_n, protect_times, floor2, split_guard,
                             refit_cells, counters)
            compact_if_half_dead(fa)
        counters[CELLS_FREED] += count
