"""Feature correction with the free-space scan (ALGORITHM.md §4, eqs. 9-10).

A feature is corrected when its 3σ ellipse intersects the scan's free-space scan, exactly:
some free cell centre has Mahalanobis distance ≤ 3 from it. Candidates are first found by
testing each live feature's 3σ bounding box (half-widths ``3·sqrt(P_xx)``, ``3·sqrt(P_yy)``)
against the free window's box, then confirmed by rasterising their 3σ ellipses as row spans
inside the window.

For the touched features, in ascending id order: ``N`` particles each are drawn at once,
``F × N`` particles, as ``μ + L z`` with ``z`` standard normal of shape ``(2, F, N)``
(x-draws then y-draws, contiguous) from the mapper's ``Generator(PCG64(seed))`` and ``L``
the Cholesky factor of ``P``. Each particle is snapped to its grid cell (computed in grid
units, ``floor((μ − origin)/res + (L/res) z)``); those in free cells are deleted (particles
outside the grid are not free). With ``M ≥ keep_fraction·N`` survivors the feature is refit
to the sample mean (eq. 9) and covariance (eq. 10, divisor ``M − 1``) of the survivors.

Decision (``refit_positions``): the spec snaps particles to cells to compare them with the
free-space grid; for the refit the default uses the survivors' own (continuous) positions.
Refitting from cell centres adds the rounding variance ``res²/12`` per axis at *every*
refit, and a feature is refit at nearly every scan that sees it, so the variance of
long-observed features grows without bound (measured: on the benchmark room the mean
feature variance with correction rose above the uncorrected one). ``"cell"`` keeps the
literal reading available. The floor ``σ_min²·I`` is added when ``M < 3`` or the sample
covariance is singular or not positive definite. With fewer survivors a feature with
``measured_times < protect_times`` is deleted, otherwise it is kept unchanged and its
``measured_times`` lowered by one. Untouched features are left exactly as they were.

Decision (``split_guard``, on by default; off = eqs. 9-10 literally): a refit whose
survivors' mean lies in a free cell of this scan — a free cone cut through the middle of a
wide feature, leaving survivors on both sides — takes the "more than 95 % deleted" branch
instead (counted in ``features_split`` as well as in deleted / protected). The spec does
not cover this case; refitting one Gaussian across the cone centres the feature in space
the scan just observed free, and the refit grows and drifts scan after scan (measured on
the simulated office: mean feature variance 1.6e-2 m² with the literal refit, 8.7e-3 with
the guard, 1.3e-2 without correction).

Cost: the touched test is a 3σ bounding-box test over the feature set's precomputed boxes
(one vector compare), then each candidate's 3σ ellipse is rasterised as row spans and
tested against the free window's per-row prefix counts (O(spans), not O(cells)).
"""

from __future__ import annotations

import numpy as np

from pipeline.config import MapperConfig
from pipeline.mapper.features_reference import FeatureSet
from pipeline.mapper.free_space import FreeSpaceScan
from pipeline.mapper.grid_raster import ellipse_spans
from pipeline.mapper.types import F64, I64, B, GridSpec, MapperCounters

# Relative determinant below which a refit covariance counts as singular.
_SINGULAR = 1e-12


def touched_features(features: FeatureSet, free: FreeSpaceScan, grid: GridSpec) -> I64:
    """Slots of live features whose 3σ ellipse contains a free cell centre, ascending."""
    if free.count == 0 or features.n == 0:
        return np.zeros(0, dtype=np.int64)
    res = grid.resolution
    h, w = free.mask.shape
    x_lo = grid.origin_x + (free.col0 + 0.5) * res
    x_hi = grid.origin_x + (free.col0 + w - 0.5) * res
    y_lo = grid.origin_y + (free.row0 + 0.5) * res
    y_hi = grid.origin_y + (free.row0 + h - 0.5) * res
    # Dead slots hold an empty box, so they never pass.
    # Boxes are stored as (x_hi, −x_lo, y_hi, −y_lo): overlap is all four ≥ these.
    window = np.array([x_lo, -x_hi, y_lo, -y_hi])[:, None]
    near = (features.box[:, : features.n] >= window).all(axis=0)
    slots = np.flatnonzero(near)
    if slots.shape[0] == 0:
        return slots.astype(np.int64)
    mean = features.mean[slots]
    cov = features.cov[slots]
    spans = ellipse_spans(mean[:, 0], mean[:, 1], cov[:, 0], cov[:, 1], cov[:, 2], 3.0, grid)
    # Only the part of each span inside the free window can meet a free cell; a span holds
    # one when the row's running count of free cells grows across it.
    c0 = np.maximum(spans.c0 - free.col0, 0)
    c1 = np.minimum(spans.c1 - free.col0, w - 1)
    r = spans.row - free.row0
    keep = (r >= 0) & (r < h) & (c0 <= c1)
    r, c0, c1 = r[keep], c0[keep], c1[keep]
    pre = free.prefix
    hit = pre[r, c1 + 1] > pre[r, c0]
    touched = np.zeros(slots.shape[0], dtype=np.bool_)
    touched[spans.owner[keep][hit]] = True
    return slots[touched].astype(np.int64)


def correct_features(
    features: FeatureSet,
    free: FreeSpaceScan,
    config: MapperConfig,
    grid: GridSpec,
    rng: np.random.Generator,
    counters: MapperCounters,
) -> None:
    """Apply §4 to every feature touched by ``free``; updates ``features`` and ``counters``."""
    slots = touched_features(features, free, grid)
    f = slots.shape[0]
    if f == 0:
        return
    n = config.n_particles
    res = grid.resolution
    inv = 1.0 / res
    mean = features.mean[slots]
    cov = features.cov[slots]
    l11 = np.sqrt(cov[:, 0])
    l21 = np.divide(cov[:, 1], l11, out=np.zeros(f), where=l11 > 0)
    l22 = np.sqrt(np.maximum(cov[:, 2] - l21 * l21, 0.0))
    # Particles in grid units relative to the cell just before the free window (one cell
    # of margin), both axes in one array z: p = z[0] (x, columns), q = z[1] (y, rows).
    # Per element the arithmetic (and its order) is that of the axis-by-axis form
    # p = l11/res·z0 + ax, q = (l22/res·z1 + ay) + (l21/res)·z0; stacking the axes only
    # halves the numpy calls.
    z = rng.standard_normal((2, f, n))
    off = np.array([free.col0 - 1, free.row0 - 1], dtype=np.float64)
    a = ((mean - _origin(grid)) * inv - off).T  # (2, f): ax, ay
    cross = (l21 * inv)[:, None] * z[0]
    scale = np.empty((2, f, 1))
    scale[0, :, 0] = l11 * inv
    scale[1, :, 0] = l22 * inv
    z *= scale
    z += a[:, :, None]
    z[1] += cross
    # Each particle's cell decides whether it dies (step 2); the refit uses the survivors'
    # continuous positions, or their cell centres with refit_positions = "cell".
    cells = np.floor(z)  # integer-valued cell index (window-relative, +1)
    survive = _outside_free(free, cells)
    m = np.count_nonzero(survive, axis=1)
    refit = m >= config.keep_fraction * n

    if refit.any():
        if config.refit_positions == "cell":
            z = cells + 0.5
        sv = survive.astype(np.float64)
        mr = m.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.empty((2, f))  # eq. 9, grid units
            # Sums along each feature's particles are numpy's pairwise sums (np.sum along a
            # contiguous axis), which the compiled kernel reproduces bit for bit.
            g[0] = (z[0] * sv).sum(axis=1) / mr
            g[1] = (z[1] * sv).sum(axis=1) / mr
            dz = z - g[:, :, None]
            dz *= sv
            dx, dy = dz
            scale_c = res * res / np.maximum(mr - 1.0, 1.0)  # eq. 10, divisor M − 1
            cxx = (dx * dx).sum(axis=1) * scale_c
            cyy = (dy * dy).sum(axis=1) * scale_c
            cxy = (dx * dy).sum(axis=1) * scale_c
            # Undo the window offset (p = 1 is the window's first column).
            mxy = _origin(grid)[:, None] + (g + off[:, None]) * res  # (2, f)
        tr = np.maximum(cxx + cyy, np.finfo(np.float64).tiny)
        det = cxx * cyy - cxy * cxy
        weak = (mr < 3) | (cxx <= 0) | (cyy <= 0) | (det <= _SINGULAR * tr * tr)
        floor = config.sigma_floor(res) ** 2
        cxx = np.where(weak, cxx + floor, cxx)
        cyy = np.where(weak, cyy + floor, cyy)
        if config.split_guard:
            # The survivors lie on both sides of a free cone: their mean is in free space.
            # The cell holding the mean, window-relative + 1 like p, q.
            in_cell = np.floor(np.where(refit, g, -1.0))
            split = refit & ~_outside_free(free, in_cell)
            if split.any():
                counters.features_split += int(split.sum())
                refit &= ~split
        moved = slots[refit]
        if moved.shape[0]:
            new_cov = np.empty((f, 3))
            new_cov[:, 0] = cxx
            new_cov[:, 1] = cxy
            new_cov[:, 2] = cyy
            features.move(moved, mxy.T[refit], new_cov[refit])
            counters.features_corrected += int(moved.shape[0])

    lost = slots[~refit]
    if lost.shape[0]:
        protected = features.measured[lost] >= config.protect_times
        features.measured[lost[protected]] -= 1
        features.delete(lost[~protected])
        counters.features_protected += int(protected.sum())
        counters.features_deleted += int((~protected).sum())


def _origin(grid: GridSpec) -> F64:
    """The grid origin (x, y), m, as an array."""
    return np.array([grid.origin_x, grid.origin_y])


def _outside_free(free: FreeSpaceScan, cells: F64) -> B:
    """Whether each cell is *not* in the free-space scan; ``cells[0]``/``cells[1]`` are
    integer-valued column/row indices relative to the window, plus one (so the window
    starts at 1), of any shape. Cells outside the window (or the grid) are not free."""
    h, w = free.mask.shape
    # A border around the window absorbs every cell outside it after clipping.
    hi = np.array([w + 1.0, h + 1.0]).reshape((2,) + (1,) * (cells.ndim - 1))
    c = np.minimum(np.maximum(cells, 0.0), hi)
    flat = c[1] * (w + 2)
    flat += c[0]
    out: B = free.padded_outside.reshape(-1)[flat.astype(np.intp)]
    return out
