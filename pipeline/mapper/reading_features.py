"""One sonar reading as a Gaussian point feature (ALGORITHM.md §1, eqs. 1-4).

A reading with an echo at range ``d`` (m) along the beam axis ``α`` (rad) from the sonar
origin ``o`` becomes ``N(μ, P)`` with ``μ = o + d (cos α, sin α)`` and
``P = R(α) diag(σ_d², σ_a²) R(α)ᵀ``, ``σ_d = σ_d0 + k_d·d`` (eq. 2) and
``σ_a = d·tan(β/2)/c_a`` (eq. 3). Covariances are stored as ``(xx, xy, yy)`` columns.

Readings without a usable echo are classified by the shared
:func:`pipeline.stages.reading_quality.classify_readings` (NaN, ±inf, negative, below r_min,
at or beyond ``r_max − ε_max``). Decision: a reading whose *geometry* (origin, α or β) is not
finite cannot be placed in the world; it is counted as ``nan`` as well.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.config import MapperConfig
from pipeline.mapper.types import F64, I64, MapperCounters, Scan
from pipeline.stages import reading_quality as rq

_SKIP_FIELD = {
    rq.NAN: "skipped_nan",
    rq.POS_INF: "skipped_pos_inf",
    rq.NEG_INF: "skipped_neg_inf",
    rq.NEGATIVE: "skipped_negative",
    rq.BELOW_MIN: "skipped_below_min",
    rq.MAX_RANGE: "skipped_max_range",
}


@dataclass(frozen=True)
class ReadingFeatures:
    """Features of the usable readings of one scan, in scan row order."""

    row: I64  # index of the reading in the scan
    mean: F64  # (m, 2) world x, y, m
    cov: F64  # (m, 3) covariance xx, xy, yy, m²
    t_ns: I64

    def __len__(self) -> int:
        return int(self.row.shape[0])


def distance_sigma(d: npt.ArrayLike, config: MapperConfig) -> F64:
    """σ_d = σ_d0 + k_d·d, m (eq. 2)."""
    return config.sigma_d0 + config.k_d * np.asarray(d, dtype=np.float64)


def lateral_sigma(d: npt.ArrayLike, fov: npt.ArrayLike, config: MapperConfig) -> F64:
    """σ_a = d·tan(β/2)/c_a, m (eq. 3); β is the full beam width, rad."""
    return np.asarray(d, dtype=np.float64) * np.tan(0.5 * np.asarray(fov)) / config.c_a


def beam_covariance(
    d: npt.ArrayLike, alpha: npt.ArrayLike, fov: npt.ArrayLike, config: MapperConfig
) -> F64:
    """World covariance ``R(α) diag(σ_d², σ_a²) R(α)ᵀ`` as ``(n, 3)`` columns xx, xy, yy (m²)."""
    sd2 = distance_sigma(d, config) ** 2
    sa2 = lateral_sigma(d, fov, config) ** 2
    a = np.asarray(alpha, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    xx = c * c * sd2 + s * s * sa2
    xy = c * s * (sd2 - sa2)
    yy = s * s * sd2 + c * c * sa2
    return np.stack([xx, xy, yy], axis=-1)


def classify_scan(scan: Scan, config: MapperConfig) -> npt.NDArray[np.int8]:
    """Reason code per reading (``reading_quality`` codes; non-finite geometry → NAN)."""
    codes = rq.classify_readings(scan.range_m, scan.min_range, scan.max_range, config.eps_max)
    bad_geometry = ~(
        np.isfinite(scan.origin_x)
        & np.isfinite(scan.origin_y)
        & np.isfinite(scan.alpha)
        & np.isfinite(scan.fov)
    )
    codes[bad_geometry] = rq.NAN
    return codes


def count_readings(codes: npt.NDArray[np.int8], counters: MapperCounters) -> None:
    """Add one scan's readings to the counters, skipped ones by reason."""
    counts = np.bincount(codes.astype(np.int64), minlength=len(rq.REASONS))
    counters.scans += 1
    counters.readings += int(codes.shape[0])
    counters.readings_used += int(counts[rq.OK])
    for code, name in _SKIP_FIELD.items():
        setattr(counters, name, getattr(counters, name) + int(counts[code]))


def reading_features(
    scan: Scan, codes: npt.NDArray[np.int8], config: MapperConfig
) -> ReadingFeatures:
    """Gaussian features (eqs. 1-4) of the readings whose code is OK, in scan row order."""
    row = np.flatnonzero(codes == rq.OK).astype(np.int64)
    d = scan.range_m[row]
    a = scan.alpha[row]
    mean = np.stack(
        [scan.origin_x[row] + d * np.cos(a), scan.origin_y[row] + d * np.sin(a)], axis=-1
    )
    cov = beam_covariance(d, a, scan.fov[row], config)
    return ReadingFeatures(row, mean, cov, scan.t_ns[row].astype(np.int64))
