"""The feature set the compiled mapper works on: its arrays, owned from Python.

Same contents and outputs as :class:`pipeline.mapper.features_reference.FeatureSet` (the numpy
reference, which the tests compare it with): Gaussian features in slots in id order, a
hash grid of ``match_distance`` buckets. The kernels of
:mod:`pipeline.mapper.kernels.features` read and change the arrays in place; this
class allocates them, grows them between kernel calls (:meth:`reserve`) and reads them
out (:meth:`table`, :meth:`variance`).
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.mapper.features_reference import bucket_layout, feature_variance
from pipeline.mapper.kernels.features import LIVE, N_SLOTS, FeatureArrays, add_features
from pipeline.mapper.types import F64, I64, FeatureTable, GridSpec


def _arrays(capacity: int, head: np.ndarray, meta: np.ndarray, geometry: np.ndarray) -> FeatureArrays:
    box = np.full((capacity, 4), -np.inf)
    return FeatureArrays(
        mean=np.zeros((capacity, 2)),
        cov=np.zeros((capacity, 3)),
        box=box,
        measured=np.zeros(capacity, dtype=np.int64),
        first_ns=np.zeros(capacity, dtype=np.int64),
        last_ns=np.zeros(capacity, dtype=np.int64),
        merges=np.zeros(capacity, dtype=np.int64),
        ids=np.full(capacity, -1, dtype=np.int64),
        alive=np.zeros(capacity, dtype=np.bool_),
        bucket=np.full(capacity, -1, dtype=np.int64),
        nxt=np.full(capacity, -1, dtype=np.int64),
        prv=np.full(capacity, -1, dtype=np.int64),
        head=head,
        meta=meta,
        geometry=geometry,
    )


class FeatureStore:
    """Gaussian point features in the world frame (means m, covariances m², times ns)."""

    def __init__(self, grid: GridSpec, match_distance: float, capacity: int = 1024) -> None:
        self.grid = grid
        self.match_distance = float(match_distance)
        size, nbx, nby = bucket_layout(grid, self.match_distance)
        geometry = np.array([grid.origin_x, grid.origin_y, 1.0 / size, nbx - 1.0, nby - 1.0,
                             float(nbx), float(nby)])
        head = np.full(nbx * nby, -1, dtype=np.int64)
        self.arrays = _arrays(capacity, head, np.zeros(3, dtype=np.int64), geometry)

    @property
    def n(self) -> int:
        """Slots in use (alive or dead)."""
        return int(self.arrays.meta[N_SLOTS])

    @property
    def capacity(self) -> int:
        return int(self.arrays.ids.shape[0])

    @property
    def mean(self) -> F64:
        return self.arrays.mean

    @property
    def cov(self) -> F64:
        return self.arrays.cov

    def __len__(self) -> int:
        return int(self.arrays.meta[LIVE])

    def reserve(self, extra: int) -> None:
        """Room for ``extra`` more features (a kernel call adds at most its readings)."""
        need = self.n + extra
        if need <= self.capacity:
            return
        old, n = self.arrays, self.n
        new = _arrays(max(2 * self.capacity, need), old.head, old.meta, old.geometry)
        for name in FeatureArrays._fields:
            if name in ("head", "meta", "geometry"):
                continue
            getattr(new, name)[:n] = getattr(old, name)[:n]
        self.arrays = new

    def add(self, mean: F64, cov: F64, t_ns: I64) -> None:
        """Append new features (measured_times = 1): means ``(m, 2)``, covariances ``(m, 3)``."""
        self.reserve(mean.shape[0])
        add_features(self.arrays, np.ascontiguousarray(mean, dtype=np.float64),
                     np.ascontiguousarray(cov, dtype=np.float64),
                     np.ascontiguousarray(t_ns, dtype=np.int64))

    def alive_slots(self) -> I64:
        """Slots of live features, ascending (= id order)."""
        return np.flatnonzero(self.arrays.alive[: self.n]).astype(np.int64)

    def table(self) -> FeatureTable:
        """Live features as columns, sorted by id."""
        s = self.alive_slots()
        a = self.arrays
        return FeatureTable(
            id=a.ids[s].copy(),
            x=a.mean[s, 0].copy(),
            y=a.mean[s, 1].copy(),
            cov_xx=a.cov[s, 0].copy(),
            cov_xy=a.cov[s, 1].copy(),
            cov_yy=a.cov[s, 2].copy(),
            measured_times=a.measured[s].copy(),
            first_seen_ns=a.first_ns[s].copy(),
            last_seen_ns=a.last_ns[s].copy(),
            merges=a.merges[s].copy(),
        )

    def variance(self) -> tuple[float, float]:
        """(mean of trace(P)/2, mean of the largest eigenvalue of P), m²; NaN when empty."""
        s = self.alive_slots()
        if s.shape[0] == 0:
            return (math.nan, math.nan)
        return feature_variance(self.arrays.cov[s])
