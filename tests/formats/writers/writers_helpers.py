"""Builders for the writer tests: small synthetic maps and feature tables.

A uniquely named module (not conftest) so other test folders' conftest files cannot shadow it.
"""

from __future__ import annotations

import numpy as np

from formats.map_types import FeatureTable, GridSpec
from pipeline.mapper.types import MapSnapshot


def make_features(
    x: list[float],
    y: list[float],
    cov: list[tuple[float, float, float]],
    measured: list[int] | None = None,
) -> FeatureTable:
    n = len(x)
    c = np.asarray(cov, dtype=np.float64).reshape(n, 3)
    return FeatureTable(
        id=np.arange(1, n + 1, dtype=np.int64),
        x=np.asarray(x, dtype=np.float64),
        y=np.asarray(y, dtype=np.float64),
        cov_xx=c[:, 0].copy(),
        cov_xy=c[:, 1].copy(),
        cov_yy=c[:, 2].copy(),
        measured_times=np.asarray(measured if measured is not None else [3] * n, dtype=np.int64),
        first_seen_ns=np.arange(n, dtype=np.int64) * 1_000_000_000 + 1_700_000_000_000_000_000,
        last_seen_ns=np.arange(n, dtype=np.int64) * 1_000_000_000 + 1_700_000_005_000_000_000,
        merges=np.arange(n, dtype=np.int64) % 3,
    )


def make_snapshot(grid: GridSpec, probability: np.ndarray, features: FeatureTable) -> MapSnapshot:
    prob = probability.astype(np.float32)
    return MapSnapshot(
        grid=grid,
        probability=prob,
        free_logodds=np.zeros(grid.shape, dtype=np.float32),
        occupied=np.nan_to_num(prob) > 0.5,
        observed=~np.isnan(prob),
        features=features,
    )
