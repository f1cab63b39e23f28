"""Angle helpers shared by every layer."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from formats.arrays import F64

__all__ = ["wrap_angle", "yaw_from_quaternion"]


def yaw_from_quaternion(qx: F64, qy: F64, qz: F64, qw: F64) -> F64:
    """Yaw (rad) of quaternions: atan2(2(wz + xy), 1 − 2(y² + z²)). A garbage quaternion
    (components near the float limit) gives a non-finite yaw, which the pose checks drop;
    numpy's overflow warning about it is silenced here, where it arises."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.asarray(np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)))


def wrap_angle(a: npt.ArrayLike) -> F64:
    """Angles wrapped to [−π, π), rad (as float64 arrays)."""
    return np.asarray((np.asarray(a, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi)
