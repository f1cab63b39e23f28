"""Principal axes of 2×2 position covariances, vectorised over features."""

from __future__ import annotations

import numpy as np

from formats.arrays import F64

__all__ = ["covariance_axes", "ellipse_polygons"]


def covariance_axes(cov_xx: F64, cov_xy: F64, cov_yy: F64) -> tuple[F64, F64, F64]:
    """``(sigma_major, sigma_minor, orientation)`` of covariances ``[[xx, xy], [xy, yy]]``.

    Sigmas are square roots of the eigenvalues (m for covariances in m²); orientation is the
    angle of the major-axis eigenvector from +x, counter-clockwise, in (−π/2, π/2] rad
    (0 for isotropic covariances). Tiny negative eigenvalues from rounding are clipped to 0.
    """
    a = np.asarray(cov_xx, dtype=np.float64)
    b = np.asarray(cov_xy, dtype=np.float64)
    c = np.asarray(cov_yy, dtype=np.float64)
    mean = 0.5 * (a + c)
    # hypot, not sqrt of a sum of squares: no overflow or cancellation for extreme values.
    radius = np.hypot(0.5 * (a - c), b)
    major = np.sqrt(np.maximum(mean + radius, 0.0))
    minor = np.sqrt(np.maximum(mean - radius, 0.0))
    theta = 0.5 * np.arctan2(2.0 * b, a - c)
    # arctan2(−0.0, negative) is −π, giving −π/2: the same axis as +π/2, which is in range.
    theta = np.where(theta <= -np.pi / 2, theta + np.pi, theta)
    return major, minor, theta


def ellipse_polygons(
    x: F64, y: F64, cov_xx: F64, cov_xy: F64, cov_yy: F64, *, k: float = 2.0, n: int = 32
) -> F64:
    """Outline points of each feature's kσ ellipse, shape (F, n, 2), in m (world frame)."""
    major, minor, theta = covariance_axes(cov_xx, cov_xy, cov_yy)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ct, st = np.cos(t)[None, :], np.sin(t)[None, :]
    u = k * major[:, None] * ct  # along the major axis
    v = k * minor[:, None] * st
    cth, sth = np.cos(theta)[:, None], np.sin(theta)[:, None]
    px = np.asarray(x, dtype=np.float64)[:, None] + u * cth - v * sth
    py = np.asarray(y, dtype=np.float64)[:, None] + u * sth + v * cth
    return np.stack([px, py], axis=-1)
