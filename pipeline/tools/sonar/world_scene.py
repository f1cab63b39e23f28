"""The surfaces a sonar's beam meets in a simulated world (``simulate``).

A reading casts a fan of rays ``ray_step`` apart across its audible cone (where the beam
loss is below the margin). Each ray stops at the first segment or circle it meets: the
distance, the incidence against that surface's normal and the surface's critical angle
(keyed by its index in the world, :mod:`pipeline.tools.sonar.surfaces`). When that surface
reflects specularly, the mirror ray is cast on from the hit point for the multipath leg.
"""

from __future__ import annotations

import math

import numpy as np

from formats.arrays import F64, I64
from pipeline.tools.simulate.world import World, circle_distances, segment_distances
from pipeline.tools.sonar.echo import Fan
from pipeline.tools.sonar.model import SonarPhysics
from pipeline.tools.sonar.surfaces import critical_angles

_MAX_PAIRS = 1 << 21  # ray × obstacle pairs evaluated at once
_EPS_M = 1e-6  # the mirror ray starts this far off the surface it leaves


def cast_surfaces(world: World, ox: F64, oy: F64, ux: F64, uy: F64) -> tuple[F64, F64, F64, I64]:
    """First hit of each ray (unit direction ``ux, uy``): distance (m, +inf none), unit
    normal at the hit (any sign) and the surface index (segments, then circles; −1 none)."""
    n = ox.shape[0]
    best = np.full(n, np.inf)
    nx = np.zeros(n)
    ny = np.zeros(n)
    key = np.full(n, -1, np.int64)
    seg = world.segments
    rows = np.arange(n)
    if seg.shape[0]:
        ax, ay = seg[None, :, 0], seg[None, :, 1]
        ex, ey = seg[None, :, 2] - ax, seg[None, :, 3] - ay
        t = segment_distances(seg, ox, oy, ux, uy)
        j = np.argmin(t, axis=1)
        best = t[rows, j]
        elen = np.hypot(ex[0, j], ey[0, j])
        nx, ny = -ey[0, j] / elen, ex[0, j] / elen
        key = np.where(np.isfinite(best), j, -1)
    cir = world.circles
    if cir.shape[0]:
        t, _ = circle_distances(cir, ox, oy, ux, uy)
        j = np.argmin(t, axis=1)
        tc = t[rows, j]
        hx = ox + tc * ux - cir[j, 0]
        hy = oy + tc * uy - cir[j, 1]
        closer = tc < best
        best = np.where(closer, tc, best)
        with np.errstate(invalid="ignore"):
            nx = np.where(closer, hx / cir[j, 2], nx)
            ny = np.where(closer, hy / cir[j, 2], ny)
        key = np.where(closer, seg.shape[0] + j, key)
    return best, nx, ny, key


def _nearby(world: World, ox: F64, oy: F64, reach: float) -> tuple[World, I64]:
    """The obstacles that can be within ``reach`` of any of the origins, and their
    surface indices in ``world``."""
    x0, x1 = float(ox.min()) - reach, float(ox.max()) + reach
    y0, y1 = float(oy.min()) - reach, float(oy.max()) + reach
    s = world.segments
    ks = ((np.maximum(s[:, 0], s[:, 2]) >= x0) & (np.minimum(s[:, 0], s[:, 2]) <= x1)
          & (np.maximum(s[:, 1], s[:, 3]) >= y0) & (np.minimum(s[:, 1], s[:, 3]) <= y1))
    c = world.circles
    kc = ((c[:, 0] + c[:, 2] >= x0) & (c[:, 0] - c[:, 2] <= x1)
          & (c[:, 1] + c[:, 2] >= y0) & (c[:, 1] - c[:, 2] <= y1))
    sub = World(s[ks], c[kc], name=world.name, bounds=world.bounds)
    return sub, np.concatenate([np.nonzero(ks)[0], s.shape[0] + np.nonzero(kc)[0]])


def world_fans(
    world: World,
    ox: F64,
    oy: F64,
    alpha: F64,
    max_range: F64,
    physics: SonarPhysics,
    seed: int,
    *,
    ray_step_rad: float = math.radians(1.0),
) -> Fan:
    """The fan of each reading: sonar origin ``ox, oy`` (m), axis ``alpha`` (rad)."""
    half = physics.audible_half_angle()
    k = max(2, math.ceil(2 * half / ray_step_rad) + 1)
    frac = np.linspace(-half, half, k)
    n = ox.shape[0]
    shape = (n, k)
    d1 = np.full(shape, np.inf)
    cos1 = np.ones(shape)
    crit1 = np.zeros(shape)
    d2 = np.full(shape, np.inf)
    cos2 = np.ones(shape)
    crit2 = np.zeros(shape)
    n_obst = max(1, world.segments.shape[0] + world.circles.shape[0])
    chunk = max(1, _MAX_PAIRS // (k * n_obst))
    reach = float(max_range.max()) if n else 0.0
    for lo in range(0, n, chunk):
        sl = slice(lo, min(n, lo + chunk))
        sub, keep = _nearby(world, ox[sl], oy[sl], reach)
        keep = np.append(keep, 0)  # indexable when nothing is near
        theta = (alpha[sl, None] + frac[None, :]).reshape(-1)
        ux, uy = np.cos(theta), np.sin(theta)
        rx, ry = np.repeat(ox[sl], k), np.repeat(oy[sl], k)
        dist, nx, ny, key = cast_surfaces(sub, rx, ry, ux, uy)
        hit = np.isfinite(dist)
        gkey = np.where(hit, keep[np.maximum(key, 0)], 0)
        crit = critical_angles(gkey, physics, seed)
        dot = ux * nx + uy * ny
        c1 = np.where(hit, np.abs(dot), 1.0)
        # The multipath leg of the rays the first surface reflects specularly.
        limit = np.repeat(max_range[sl], k) - dist
        m = np.nonzero(hit & (c1 < np.cos(crit)) & (limit > 0))[0]
        e2 = np.full(dist.shape, np.inf)
        c2 = np.ones(dist.shape)
        k2 = np.zeros(dist.shape)
        if m.size:
            mx, my = ux[m] - 2 * dot[m] * nx[m], uy[m] - 2 * dot[m] * ny[m]
            hx, hy = rx[m] + dist[m] * ux[m] + _EPS_M * mx, ry[m] + dist[m] * uy[m] + _EPS_M * my
            t2, n2x, n2y, key2 = cast_surfaces(sub, hx, hy, mx, my)
            got = np.isfinite(t2) & (t2 <= limit[m])
            mm = m[got]
            e2[mm] = t2[got] + _EPS_M
            c2[mm] = np.abs(mx[got] * n2x[got] + my[got] * n2y[got])
            k2[mm] = critical_angles(keep[key2[got]], physics, seed)
        d1[sl] = np.where(hit, dist, np.inf).reshape(-1, k)
        cos1[sl] = c1.reshape(-1, k)
        crit1[sl] = crit.reshape(-1, k)
        d2[sl] = e2.reshape(-1, k)
        cos2[sl] = c2.reshape(-1, k)
        crit2[sl] = k2.reshape(-1, k)
    off = np.broadcast_to(np.abs(frac)[None, :], shape).copy()
    return Fan(off, d1, cos1, crit1, d2, cos2, crit2)
