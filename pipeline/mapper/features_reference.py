"""The map's feature set: Gaussian obstacle features, a spatial hash grid, Kalman merge.

ALGORITHM.md §2, eqs. 5-8. Each reading feature ``N(μ_z, P_z)`` is matched to the existing
feature with the nearest mean (Euclidean, ties → lowest id); if that distance is
``< match_distance`` the two are merged with the Kalman update (map feature = prediction,
reading = measurement, observation matrix I)::

    ν = μ_z − μ_f;  K = P_f (P_f + P_z)⁻¹;  μ_f ← μ_f + K ν;  P_f ← (I − K) P_f  (symmetrised)

otherwise the reading becomes a new feature with ``measured_times = 1``.

Decisions:

* **Order and semantics.** Readings of a scan are merged in the scan's row order, with
  *sequential* semantics (the paper's natural reading): a reading may merge into a feature
  created or moved by an earlier reading of the same scan. This is computed without a
  per-reading loop in the common case: all remaining readings are matched against the
  current set at once, and the longest prefix whose readings cannot see each other's
  changes (no earlier reading's old or new feature position within ``match_distance`` of a
  later reading) is applied in one vectorised step; the rest is matched again against the
  updated set. Results equal one-by-one processing exactly.
* **Spatial index.** A dense grid of buckets ``match_distance`` wide (or wider for huge
  maps, to bound memory) over the map grid. Each non-empty bucket owns a row of a padded
  pool of slots (insertion order; a slot that leaves leaves a hole, -1); a full row
  triggers one vectorised rebuild of every row without holes, with room for twice the
  fullest bucket. A query gathers the used part of the 3×3 buckets' rows around each point
  as flat arrays (no Python loop over slots or lists), so it never scans all features.
  Points outside the grid fall into the clamped border buckets (clamping is 1-Lipschitz,
  so the 3×3 neighbourhood still holds every feature within reach).
* **3σ boxes.** Each slot also keeps its 3σ bounding box (``box``, as ``x_hi, −x_lo,
  y_hi, −y_lo`` so an overlap test is one ``≥`` per row), updated on every
  change, so the correction's candidate test is a few vector compares.
* **Storage.** Columns in growable numpy arrays; slots are appended in id order, deleted
  slots are compacted away (stably) when they make up half the store, so slot order is id
  order and tables come out sorted by id without a sort.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from pipeline.mapper.types import F64, I64, FeatureTable, GridSpec

_MAX_BUCKETS = 4_000_000  # bounds the index's memory on very large grids (32 MB of int64)
_OFFS = np.array([-1, 0, 1], dtype=np.int64)
_BIG = np.iinfo(np.int64).max
_INF1 = np.array([np.inf])
_BIG1 = np.array([_BIG], dtype=np.int64)
_UPPER: dict[int, npt.NDArray[np.bool_]] = {}
# Slots in the bucket pool: int32 halves the index's memory (rows × twice the fullest bucket).
_SLOT = np.int32


def _upper(k: int) -> npt.NDArray[np.bool_]:
    """The strictly upper triangular ``k × k`` mask ``[i, j] = i < j`` (cached, read-only)."""
    mask = _UPPER.get(k)
    if mask is None:
        mask = np.triu(np.ones((k, k), dtype=np.bool_), k=1)
        mask.flags.writeable = False
        _UPPER[k] = mask
    return mask


def bucket_layout(grid: GridSpec, match_distance: float) -> tuple[float, int, int]:
    """The spatial index's bucket size (m) and bucket columns, rows over ``grid``:
    ``match_distance`` wide, or wider when that would exceed ``_MAX_BUCKETS``."""
    span_x = grid.width * grid.resolution
    span_y = grid.height * grid.resolution
    size = float(match_distance)
    if (span_x / size + 1) * (span_y / size + 1) > _MAX_BUCKETS:
        size = math.sqrt(span_x * span_y / _MAX_BUCKETS) + 1e-9
    size = max(size, float(match_distance))
    return size, math.ceil(span_x / size) + 1, math.ceil(span_y / size) + 1


def kalman_merge(mu_f: F64, p_f: F64, mu_z: F64, p_z: F64) -> tuple[F64, F64]:
    """Eqs. 5-8 for ``n`` pairs at once: means ``(n, 2)`` (m), covariances ``(n, 3)`` xx, xy, yy (m²).

    Returns the merged ``(μ, P)``; ``P`` is symmetrised (the mean of its off-diagonals).
    """
    fxx, fxy, fyy = p_f[:, 0], p_f[:, 1], p_f[:, 2]
    sxx, sxy, syy = fxx + p_z[:, 0], fxy + p_z[:, 1], fyy + p_z[:, 2]
    det = sxx * syy - sxy * sxy
    ixx, ixy, iyy = syy / det, -sxy / det, sxx / det
    k11 = fxx * ixx + fxy * ixy
    k12 = fxx * ixy + fxy * iyy
    k21 = fxy * ixx + fyy * ixy
    k22 = fxy * ixy + fyy * iyy
    nx = mu_z[:, 0] - mu_f[:, 0]
    ny = mu_z[:, 1] - mu_f[:, 1]
    mu = np.empty((nx.shape[0], 2))
    mu[:, 0] = mu_f[:, 0] + k11 * nx + k12 * ny
    mu[:, 1] = mu_f[:, 1] + k21 * nx + k22 * ny
    a11, a12, a21, a22 = 1.0 - k11, -k12, -k21, 1.0 - k22
    pxx = a11 * fxx + a12 * fxy
    pxy = a11 * fxy + a12 * fyy
    pyx = a21 * fxx + a22 * fxy
    pyy = a21 * fxy + a22 * fyy
    p = np.empty((nx.shape[0], 3))
    p[:, 0] = pxx
    p[:, 1] = 0.5 * (pxy + pyx)
    p[:, 2] = pyy
    return mu, p


class FeatureSet:
    """Gaussian point features in the world frame (means m, covariances m², times ns)."""

    mean: F64  # (capacity, 2)
    cov: F64  # (capacity, 3) xx, xy, yy
    measured: I64
    first_ns: I64
    last_ns: I64
    merges: I64
    ids: I64
    alive: npt.NDArray[np.bool_]
    box: F64  # (4, capacity): 3σ bounding box x_hi, −x_lo, y_hi, −y_lo, m (dead: −inf)
    _bucket: I64  # bucket of each slot (-1 when unlinked) and its position in the row
    _pos: I64

    def __init__(self, grid: GridSpec, match_distance: float, capacity: int = 1024) -> None:
        self.grid = grid
        self.match_distance = float(match_distance)
        self._bucket_size, self._nbx, self._nby = bucket_layout(grid, self.match_distance)
        self._b_origin = np.array([grid.origin_x, grid.origin_y])
        self._b_last = np.array([self._nbx - 1, self._nby - 1], dtype=np.float64)
        # Bucket → row of the pool (0 = the shared, always empty row); a row lists the
        # bucket's slots in insertion order, with holes (-1) where slots left.
        self._row_of = np.zeros(self._nbx * self._nby, dtype=np.int64)
        self._cap = 8
        self._pool = np.full((256, self._cap), -1, dtype=_SLOT)
        self._fill = np.zeros(256, dtype=np.int64)
        self._rows_used = 1
        self.n = 0  # slots in use (alive or dead)
        self.next_id = 0
        self._live = 0
        self._alloc(capacity)

    # ------------------------------------------------------------------ storage

    def _alloc(self, capacity: int) -> None:
        old = self.n
        prev = getattr(self, "mean", None)

        def grow(name: str, shape: tuple[int, ...], dtype: type, fill: float | int) -> None:
            arr: np.ndarray = np.full(shape, fill, dtype=dtype)
            if prev is not None:
                arr[:old] = getattr(self, name)[:old]
            setattr(self, name, arr)

        grow("mean", (capacity, 2), np.float64, 0.0)
        grow("cov", (capacity, 3), np.float64, 0.0)
        grow("measured", (capacity,), np.int64, 0)
        grow("first_ns", (capacity,), np.int64, 0)
        grow("last_ns", (capacity,), np.int64, 0)
        grow("merges", (capacity,), np.int64, 0)
        grow("ids", (capacity,), np.int64, -1)
        grow("alive", (capacity,), np.bool_, False)
        grow("_bucket", (capacity,), np.int64, -1)
        grow("_pos", (capacity,), np.int64, -1)
        self.capacity = capacity
        box = np.full((4, capacity), -np.inf)
        if prev is not None:
            box[:, :old] = self.box[:, :old]
        self.box = box

    def __len__(self) -> int:
        return self._live

    def alive_slots(self) -> I64:
        """Slots of live features, ascending (= id order)."""
        return np.flatnonzero(self.alive[: self.n]).astype(np.int64)

    def _set_gaussians(self, slots: I64, mean: F64, cov: F64) -> None:
        self.mean[slots] = mean
        self.cov[slots] = cov
        h = 3.0 * np.sqrt(cov[:, 0::2])  # half-widths x, y
        self.box[0::2, slots] = (mean + h).T
        self.box[1::2, slots] = -(mean - h).T

    def add(self, mean: F64, cov: F64, t_ns: I64) -> I64:
        """Append new features (measured_times = 1); returns their slots."""
        m = mean.shape[0]
        if self.n + m > self.capacity:
            self._alloc(max(2 * self.capacity, self.n + m))
        slots = np.arange(self.n, self.n + m, dtype=np.int64)
        self._set_gaussians(slots, mean, cov)
        self.measured[slots] = 1
        self.first_ns[slots] = t_ns
        self.last_ns[slots] = t_ns
        self.merges[slots] = 0
        self.ids[slots] = np.arange(self.next_id, self.next_id + m)
        self.alive[slots] = True
        self.n += m
        self.next_id += m
        self._live += m
        self._link(slots, self._buckets_of(mean))
        return slots

    def move(self, slots: I64, mean: F64, cov: F64) -> None:
        """Replace the Gaussians of existing features (re-bucketing those that moved far)."""
        self._set_gaussians(slots, mean, cov)
        new_bucket = self._buckets_of(mean)
        moved = new_bucket != self._bucket[slots]
        if moved.any():
            self._unlink(slots[moved])
            self._link(slots[moved], new_bucket[moved])

    def delete(self, slots: I64) -> None:
        """Remove features; compacts the store when half of it is dead."""
        if slots.shape[0] == 0:
            return
        self._unlink(slots)
        self.alive[slots] = False
        self.box[:, slots] = -np.inf
        self._live -= int(slots.shape[0])
        dead = self.n - self._live
        if dead >= 1024 and 2 * dead >= self.n:
            self._compact()

    def _compact(self) -> None:
        keep = self.alive_slots()
        m = keep.shape[0]
        for name in ("mean", "cov", "measured", "first_ns", "last_ns", "merges", "ids", "alive"):
            arr = getattr(self, name)
            arr[:m] = arr[keep]
        self.box[:, :m] = self.box[:, keep]
        self.box[:, m:] = -np.inf
        self.alive[m:] = False
        self.ids[m:] = -1
        self.n = m
        self._rebuild_index()

    # ------------------------------------------------------------------ spatial index

    def _buckets_of(self, mean: F64) -> I64:
        bx, by = self._bucket_xy(mean)
        return by * self._nbx + bx

    def _bucket_xy(self, mean: F64) -> tuple[I64, I64]:
        # Means are finite (non-finite readings never become features). Both axes at once
        # (per-element the same arithmetic as axis by axis; fewer numpy calls).
        f = (mean - self._b_origin) * (1.0 / self._bucket_size)
        b = np.floor(np.minimum(np.maximum(f, 0.0), self._b_last)).astype(np.int64)
        return b[:, 0], b[:, 1]

    def _link(self, slots: I64, buckets: I64) -> None:
        """Append slots to their buckets' rows (allocating rows for new buckets)."""
        rows = self._row_of[buckets]
        fresh = rows == 0
        if fresh.any():
            new_b = buckets[fresh]
            if new_b.shape[0] > 1:
                new_b = np.unique(new_b)
            k = new_b.shape[0]
            if self._rows_used + k > self._pool.shape[0]:
                self._grow_pool(max(2 * self._pool.shape[0], self._rows_used + k), self._cap)
            self._row_of[new_b] = np.arange(self._rows_used, self._rows_used + k)
            self._rows_used += k
            rows = self._row_of[buckets]
        if slots.shape[0] == 1:
            rank = np.zeros(1, dtype=np.int64)
        else:
            # Rank of each slot among those going to the same row, in input order.
            order = np.argsort(rows, kind="stable")
            rs = rows[order]
            idx = np.arange(rs.shape[0])
            head = np.empty(rs.shape[0], dtype=np.bool_)
            head[0] = True
            np.not_equal(rs[1:], rs[:-1], out=head[1:])
            first = np.maximum.accumulate(np.where(head, idx, 0))
            rank = np.empty_like(idx)
            rank[order] = idx - first
        pos = self._fill[rows] + rank
        if int(pos.max()) >= self._cap:
            # A row is full: rebuild every row without holes (and wider if still needed).
            self._bucket[slots] = buckets
            self._rebuild_index()
            return
        self._pool[rows, pos] = slots
        np.maximum.at(self._fill, rows, pos + 1)
        self._bucket[slots] = buckets
        self._pos[slots] = pos

    def _unlink(self, slots: I64) -> None:
        """Leave holes (-1) where the slots were; rows are compacted on rebuild."""
        self._pool[self._row_of[self._bucket[slots]], self._pos[slots]] = -1
        self._bucket[slots] = -1

    def _grow_pool(self, rows: int, cap: int) -> None:
        pool = np.full((rows, cap), -1, dtype=_SLOT)
        old = self._pool
        pool[: old.shape[0], : old.shape[1]] = old
        fill = np.zeros(rows, dtype=np.int64)
        fill[: self._fill.shape[0]] = self._fill
        self._pool, self._fill, self._cap = pool, fill, cap

    def _rebuild_index(self) -> None:
        """Rebuild every bucket row at once, in slot order, without holes."""
        slots = self.alive_slots()
        self._row_of[:] = 0
        self._bucket[: self.capacity] = -1
        if slots.shape[0] == 0:
            self._pool[:] = -1
            self._fill[:] = 0
            self._rows_used = 1
            return
        b = self._buckets_of(self.mean[slots])
        order = np.argsort(b, kind="stable")  # slots ascending within a bucket
        s, b = slots[order], b[order]
        idx = np.arange(s.shape[0])
        start = np.concatenate(([True], b[1:] != b[:-1]))
        first = np.maximum.accumulate(np.where(start, idx, 0))
        pos = idx - first
        row = np.cumsum(start)  # row 0 stays the empty row
        n_rows = int(row[-1]) + 1
        # Room for growth: twice the fullest bucket.
        cap = max(self._cap, 2 * (int(pos.max()) + 1))
        self._pool = np.full((max(n_rows + 64, self._pool.shape[0]), cap), -1, dtype=_SLOT)
        self._fill = np.zeros(self._pool.shape[0], dtype=np.int64)
        self._cap = cap
        self._pool[row, pos] = s
        np.maximum.at(self._fill, row, pos + 1)
        self._row_of[b[start]] = row[start]
        self._rows_used = n_rows
        self._bucket[s] = b
        self._pos[s] = pos

    def nearest(self, points: F64) -> tuple[I64, F64]:
        """Slot of the nearest live feature to each point among the 3×3 buckets around it
        (ties → lowest slot), and its distance, m; ``(-1, inf)`` where there is none."""
        m = points.shape[0]
        if m == 0 or self._live == 0:
            return np.full(m, -1, dtype=np.int64), np.full(m, np.inf)
        bx, by = self._bucket_xy(points)
        nx = np.minimum(np.maximum(bx[:, None] + _OFFS, 0), self._nbx - 1)
        ny = np.minimum(np.maximum(by[:, None] + _OFFS, 0), self._nby - 1)
        ny *= self._nbx
        rows = self._row_of[(ny[:, :, None] + nx[:, None, :]).reshape(-1)]
        # Gather the used part of the 9 rows of every point as one flat index into the pool
        # (clamping may repeat a bucket at the border; a repeated candidate changes neither
        # the minimum nor the tie-break).
        cnt = self._fill[rows]
        ends = np.cumsum(cnt)
        total = int(ends[-1])
        if total == 0:
            return np.full(m, -1, dtype=np.int64), np.full(m, np.inf)
        flat = np.repeat(rows * self._cap + cnt - ends, cnt)
        flat += np.arange(total)
        cand = self._pool.reshape(-1)[flat]
        per = cnt.reshape(m, 9).sum(axis=1)  # candidates of each point
        s = np.maximum(cand, 0).astype(np.int64)  # holes (-1) read slot 0, distance inf below
        diff = self.mean[s] - np.repeat(points, per, axis=0)
        d = np.hypot(diff[:, 0], diff[:, 1])
        d[cand < 0] = np.inf
        # Per point: the minimum distance, then the lowest slot at that distance. A point
        # without candidates starts at ``total``: the appended sentinel answers it.
        starts = np.cumsum(per) - per
        dmin = np.minimum.reduceat(np.concatenate((d, _INF1)), starts)
        dmin[per == 0] = np.inf
        key = np.where(d == np.repeat(dmin, per), s, _BIG)
        smin = np.minimum.reduceat(np.concatenate((key, _BIG1)), starts)
        return np.where(dmin < np.inf, smin, -1), dmin

    # ------------------------------------------------------------------ merging

    def merge_readings(self, mean: F64, cov: F64, t_ns: I64) -> tuple[int, int]:
        """Merge reading features in row order, sequential semantics (see module doc).

        Returns ``(created, merged)`` counts.
        """
        created = merged = 0
        start, m = 0, mean.shape[0]
        reach = self.match_distance * (1.0 + 1e-9)  # conservative: a tie re-queries
        while start < m:
            stop = min(m, start + 512)  # bounds the pairwise check below
            q, pz, tq = mean[start:stop], cov[start:stop], t_ns[start:stop]
            k = q.shape[0]
            slot, dist = self.nearest(q)
            hit = dist < self.match_distance
            fs = slot[hit]
            mu_f = self.mean[fs]
            mu_m, p_m = kalman_merge(mu_f, self.cov[fs], q[hit], pz[hit])
            n_ok = k
            if k > 1:
                # Reading j sees the state left by readings i < j only through features
                # within reach of its mean: the new (rows < k) and old (rows >= k)
                # positions of what i changed; a reading that created a feature has no old
                # position (NaN, never within reach).
                pos = np.full((2 * k, 2), np.nan)
                pos[:k] = q
                pos[:k][hit] = mu_m
                pos[k:][hit] = mu_f
                near = np.hypot(pos[:, None, 0] - q[None, :, 0], pos[:, None, 1] - q[None, :, 1])
                near = near < reach
                seen = near[:k] | near[k:]
                seen &= _upper(k)  # [i, j], i < j
                conflict = np.flatnonzero(seen.any(axis=0))
                if conflict.shape[0]:
                    n_ok = int(conflict[0])
            take_hit = hit[:n_ok]
            n_hit = int(np.count_nonzero(take_hit))
            if n_hit:
                s = slot[:n_ok][take_hit]
                self.move(s, mu_m[:n_hit], p_m[:n_hit])
                self.measured[s] += 1
                self.merges[s] += 1
                self.last_ns[s] = tq[:n_ok][take_hit]
                merged += n_hit
            if n_hit < n_ok:
                new = np.flatnonzero(~take_hit)
                self.add(q[new], pz[new], tq[new])
                created += new.shape[0]
            start += n_ok
        return created, merged

    # ------------------------------------------------------------------ outputs

    def table(self) -> FeatureTable:
        """Live features as columns, sorted by id."""
        s = self.alive_slots()
        return FeatureTable(
            id=self.ids[s].copy(),
            x=self.mean[s, 0].copy(),
            y=self.mean[s, 1].copy(),
            cov_xx=self.cov[s, 0].copy(),
            cov_xy=self.cov[s, 1].copy(),
            cov_yy=self.cov[s, 2].copy(),
            measured_times=self.measured[s].copy(),
            first_seen_ns=self.first_ns[s].copy(),
            last_seen_ns=self.last_ns[s].copy(),
            merges=self.merges[s].copy(),
        )

    def variance(self) -> tuple[float, float]:
        """(mean of trace(P)/2, mean of the largest eigenvalue of P), m²; NaN when empty."""
        s = self.alive_slots()
        if s.shape[0] == 0:
            return (math.nan, math.nan)
        return feature_variance(self.cov[s])


def feature_variance(cov: F64) -> tuple[float, float]:
    """ALGORITHM.md §7 for covariances ``(n, 3)``: mean trace/2 and mean largest eigenvalue, m²."""
    if cov.shape[0] == 0:
        return (math.nan, math.nan)
    xx, xy, yy = cov[:, 0], cov[:, 1], cov[:, 2]
    half_trace = 0.5 * (xx + yy)
    lam_max = half_trace + np.sqrt((0.5 * (xx - yy)) ** 2 + xy * xy)
    return (float(half_trace.mean()), float(lam_max.mean()))


def empty_table() -> FeatureTable:
    """A feature table with no rows."""
    i = np.zeros(0, dtype=np.int64)
    f = np.zeros(0, dtype=np.float64)
    return FeatureTable(i, f, f, f, f, f, i, i, i, i)
