"""Submaps: the echoes of a short stretch of odometry pooled into one local point set.

Sparse sonar sees too little in one scan to match, so echoes are pooled over about
``travel_m`` of driven path (the odometry is locally good): submap ``k`` holds the echoes
whose odometry path length lies in ``[k·travel_m, (k+1)·travel_m)``, and a stretch with
fewer than ``min_echoes`` echoes joins the next one (the last joins the one before). Each
submap's **anchor** is the odometry pose of its middle echo; its points are expressed in
the anchor's frame through the odometry, so moving the anchor moves the whole submap
rigidly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.arrays import F64, I64
from pipeline.refine.echoes import Echoes
from pipeline.se2 import between, transform_points


@dataclass(frozen=True)
class Submap:
    """One submap: its anchor (stamp, odometry pose, odometry path length) and points."""

    t_ns: int
    anchor: F64  # (3,) odometry pose x, y, yaw
    path_m: float  # odometry path length from the start to the anchor
    px: F64  # (echoes, arc samples) points in the anchor frame, m
    py: F64
    ox: F64 | None = None  # (echoes,) each echo's sensor position in the anchor frame, m
    oy: F64 | None = None

    def __len__(self) -> int:
        return int(self.px.shape[0])


def path_length(x: F64, y: F64) -> F64:
    """Path length (m) from the first pose to each pose of the track ``(x, y)`` (none for
    no pose)."""
    return np.concatenate([np.zeros(min(len(x), 1)), np.cumsum(np.hypot(np.diff(x), np.diff(y)))])


def path_length_at(track_t: I64, track_x: F64, track_y: F64, t_ns: I64) -> F64:
    """Odometry path length (m) from the first pose to each stamp (linear in between)."""
    rel = (track_t - track_t[0]).astype(np.float64)
    return np.asarray(np.interp((t_ns - track_t[0]).astype(np.float64), rel,
                                path_length(track_x, track_y)))


def build_submaps(
    echoes: Echoes, path_m: F64, *, travel_m: float, min_echoes: int, max_points: int
) -> list[Submap]:
    """Cut the echoes (time order; ``path_m`` = path length at each) into submaps."""
    n = len(echoes)
    if n == 0:
        return []
    key = np.floor(path_m / travel_m).astype(np.int64)
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    bounds = np.r_[starts, n].tolist()
    groups: list[tuple[int, int]] = []
    a = bounds[0]
    for b in bounds[1:]:
        if b - a >= min_echoes:
            groups.append((a, b))
            a = b
    if a < n:  # a short tail joins the submap before it
        if groups:
            groups[-1] = (groups[-1][0], n)
        else:
            groups.append((a, n))
    out: list[Submap] = []
    for a, b in groups:
        mid = (a + b) // 2
        anchor = echoes.odo[mid].copy()
        idx = np.arange(a, b)
        if idx.shape[0] > max_points:
            idx = idx[np.linspace(0, idx.shape[0] - 1, max_points).round().astype(np.int64)]
        wx, wy = transform_points(echoes.odo[idx][:, None, :], echoes.bx[idx], echoes.by[idx])
        local = between(anchor, np.stack([wx, wy, np.zeros_like(wx)], axis=-1))
        sx, sy = transform_points(echoes.odo[idx], echoes.sx[idx], echoes.sy[idx])
        sensor = between(anchor, np.stack([sx, sy, np.zeros_like(sx)], axis=-1))
        out.append(Submap(int(echoes.t_ns[mid]), anchor, float(path_m[mid]),
                          np.ascontiguousarray(local[..., 0]), np.ascontiguousarray(local[..., 1]),
                          np.ascontiguousarray(sensor[:, 0]), np.ascontiguousarray(sensor[:, 1])))
    return out
