"""Per-surface specular cut-offs: a log-normal draw that is a pure function of the surface.

A surface is named by an integer key (a world segment's index in ``simulate``; a patch of
``surface_patch_m`` × ``surface_patch_m`` of the building in ``emulate``). Its critical
angle is ``median · exp(spread · z)`` with ``z`` a standard normal drawn by hashing
(key, seed) with splitmix64, so the same surface keeps its finish in every reading, in any
order and in any process: a smooth wall stays silent whenever it is seen obliquely.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from formats.arrays import F64
from pipeline.tools.sonar.model import SonarPhysics

_U64 = np.uint64


def _splitmix(x: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    """The splitmix64 finaliser (wrapping uint64 arithmetic)."""
    with np.errstate(over="ignore"):
        z = x + _U64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> _U64(30))) * _U64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> _U64(27))) * _U64(0x94D049BB133111EB)
        return z ^ (z >> _U64(31))


def _uniform(keys: npt.NDArray[np.int64], seed: int, stream: int) -> F64:
    """Uniform in (0, 1) per key, a pure function of (key, seed, stream)."""
    k = keys.astype(np.int64).view(np.uint64)
    mixed = _splitmix(k ^ _splitmix(np.full(k.shape, (seed << 2) + stream, np.int64).view(np.uint64)))
    return ((mixed >> _U64(11)).astype(np.float64) + 0.5) / float(1 << 53)


def critical_angles(keys: npt.NDArray[np.int64], physics: SonarPhysics, seed: int) -> F64:
    """Critical angle (rad) of each surface key: log-normal around the median."""
    u1 = _uniform(keys, seed, 1)
    u2 = _uniform(keys, seed, 2)
    z = np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * math.pi * u2)  # Box–Muller
    deg = physics.critical_angle_median_deg * np.exp(physics.critical_angle_spread * z)
    return np.radians(np.minimum(deg, 90.0))


def patch_keys(x: F64, y: F64, patch_m: float) -> npt.NDArray[np.int64]:
    """Integer key of the ``patch_m`` square that holds each world point."""
    ix = np.floor(x / patch_m).astype(np.int64)
    iy = np.floor(y / patch_m).astype(np.int64)
    return (ix * np.int64(2_147_483_629)) ^ iy
