"""Angle helpers shared by every layer."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from formats.arrays import F64

__all__ = ["wrap_angle"]


def wrap_angle(a: npt.ArrayLike) -> F64:
    """Angles wrapped to [−π, π), rad (as float64 arrays)."""
    return np.asarray((np.asarray(a, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi)
