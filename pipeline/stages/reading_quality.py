"""Why a range reading cannot become an obstacle feature (REP 117 and the sensor limits).

Shared by the mapper (which skips such readings, ALGORITHM.md §1), the pipeline's metrics
and ``sonarmap validate``, so every place counts the same reasons the same way.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

OK = 0
NAN = 1  # REP 117: erroneous / invalid
POS_INF = 2  # REP 117: nothing detected within range
NEG_INF = 3  # REP 117: object too close to measure
NEGATIVE = 4
BELOW_MIN = 5  # d < r_min
MAX_RANGE = 6  # d >= r_max - eps_max: no echo

REASONS: dict[int, str] = {
    OK: "ok",
    NAN: "nan",
    POS_INF: "pos_inf",
    NEG_INF: "neg_inf",
    NEGATIVE: "negative",
    BELOW_MIN: "below_min",
    MAX_RANGE: "max_range",
}


def classify_readings(
    range_m: npt.ArrayLike,
    min_range: npt.ArrayLike,
    max_range: npt.ArrayLike,
    eps_max: float,
) -> npt.NDArray[np.int8]:
    """Reason code per reading (``OK`` when it has a usable echo).

    The first matching rule wins, in the order NaN, +inf, −inf, negative, below r_min,
    at or beyond ``r_max − eps_max``. Limits that are NaN or ≤ 0 are treated as absent
    (no lower bound / no upper bound).
    """
    d = np.asarray(range_m, dtype=np.float64)
    lo = np.broadcast_to(np.asarray(min_range, dtype=np.float64), d.shape)
    hi = np.broadcast_to(np.asarray(max_range, dtype=np.float64), d.shape)
    code = np.zeros(d.shape, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        has_hi = np.isfinite(hi) & (hi > 0)
        has_lo = np.isfinite(lo) & (lo > 0)
        rules = [
            (np.isnan(d), NAN),
            (d == np.inf, POS_INF),
            (d == -np.inf, NEG_INF),
            (d < 0, NEGATIVE),
            (has_lo & (d < lo), BELOW_MIN),
            (has_hi & (d >= hi - eps_max), MAX_RANGE),
        ]
    for mask, reason in reversed(rules):
        code[mask] = reason
    return code


def count_reasons(codes: npt.NDArray[np.int8]) -> dict[str, int]:
    """``{reason name: count}`` for every reason (zeros included), in code order."""
    counts = np.bincount(codes.astype(np.int64), minlength=len(REASONS))
    return {REASONS[i]: int(counts[i]) for i in sorted(REASONS)}
