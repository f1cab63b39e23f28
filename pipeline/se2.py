"""SE(2) poses as arrays ``(x, y, θ)`` (m, m, rad): composition, inverse, relative motion,
points moved by a pose (used by pose refinement, evaluation and emulation).

Every function is vectorised: its arguments are arrays of poses (last axis of size 3) or
single poses; angles come out wrapped to [−π, π).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64


def compose(a: npt.ArrayLike, b: npt.ArrayLike) -> F64:
    """``a ∘ b``: pose ``b`` given in frame ``a``, expressed in ``a``'s parent frame."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack(
        [
            a[..., 0] + c * b[..., 0] - s * b[..., 1],
            a[..., 1] + s * b[..., 0] + c * b[..., 1],
            wrap_angle(a[..., 2] + b[..., 2]),
        ],
        axis=-1,
    )


def inverse(a: npt.ArrayLike) -> F64:
    """``a⁻¹``."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack(
        [-c * a[..., 0] - s * a[..., 1], s * a[..., 0] - c * a[..., 1], wrap_angle(-a[..., 2])], axis=-1
    )


def between(a: npt.ArrayLike, b: npt.ArrayLike) -> F64:
    """``a⁻¹ ∘ b``: pose ``b`` in the frame of pose ``a``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])], axis=-1)


def transform_points(pose: npt.ArrayLike, px: F64, py: F64) -> tuple[F64, F64]:
    """Points ``(px, py)`` given in the frame of ``pose``, in the pose's parent frame."""
    p = np.asarray(pose, dtype=np.float64)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    return p[..., 0] + c * px - s * py, p[..., 1] + s * px + c * py
