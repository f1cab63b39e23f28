"""Compiled Hough vote of the echoes' tangent lines (ALGORITHM.md §11, wall lines).

An echo of range ``r`` from a sonar at ``(ox, oy)`` is tangent to the wall that answered
it: for every line normal ψ inside the cone the wall may be the line of normal ψ touched at
``(ox, oy) + r·(cos ψ, sin ψ)``. Per reading, each direction bin's centre ψ inside the cone
(``bins`` equal bins of the normal line over [0, π); a centre on the cone's edge counts) adds one vote at its touching cell in
``votes[bin]`` (saturating). Deterministic.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from pipeline.mapper.types import F64

EDGE = 1e-9  # bins: a cone edge this close to a bin's centre reaches it (rounding, not physics)


@njit(cache=True)
def vote_tangents(ox: F64, oy: F64, alpha: F64, half: F64, r: F64, gx: float, gy: float,
                  res: float, votes: npt.NDArray[np.uint16]) -> None:
    """Add each echo's tangent votes to ``votes`` (``(bins, height, width)``, uint16)."""
    bins, height, width = votes.shape
    step = math.pi / bins
    for i in range(len(r)):
        if not r[i] > 0.0:
            continue
        # A bin centre on the cone's edge is inside: mounting angles and beam widths in
        # whole degrees put edges on centres, and a yaw read from a quaternion or from
        # text differs in its last bits (EDGE keeps every log format's votes the same).
        j0 = math.ceil((alpha[i] - half[i]) / step - 0.5 - EDGE)
        j1 = math.floor((alpha[i] + half[i]) / step - 0.5 + EDGE)
        for j in range(j0, j1 + 1):
            psi = (j + 0.5) * step
            col = math.floor((ox[i] + r[i] * math.cos(psi) - gx) / res)
            row = math.floor((oy[i] + r[i] * math.sin(psi) - gy) / res)
            if 0 <= row < height and 0 <= col < width:
                b = j % bins
                if votes[b, row, col] < 65535:
                    votes[b, row, col] += 1
