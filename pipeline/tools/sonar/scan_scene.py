"""The surfaces a sonar's beam meets, from one laser scan (``emulate`` per scan).

The laser endpoints inside a sonar's audible cone (where the beam loss is below the
margin: wider than the nominal cone for strong echoes) are the rays of its fan: off-axis angle and
distance from the sonar's origin. Each endpoint's surface normal is fitted (principal
axis) to it and its neighbouring endpoints of the same scan (±``NORMAL_HALF_WINDOW``
beams, closer than ``0.25 m + 0.25·r``); an endpoint with no neighbour is a small object
(a pole, a leg) and faces the sonar. The critical angle is that of the building patch the
endpoint lies in (:mod:`pipeline.tools.sonar.surfaces`).

The multipath leg: from the endpoint along the mirror direction, the ray is marched in
``GHOST_STEP_M`` steps through the scan's free space (the star-shaped region the laser
saw: nearer than the return of the laser beam at that bearing) until it leaves it; the
laser endpoint there is the second surface. A mirror ray that leaves the laser's field of
view has no second surface (unknown there).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64
from formats.laser_log import LaserLog
from pipeline.tools.sonar.echo import Fan
from pipeline.tools.sonar.model import SonarPhysics
from pipeline.tools.sonar.surfaces import critical_angles, patch_keys
from pipeline.tools.sonar_ring import SonarRing

NORMAL_HALF_WINDOW = 2  # beams either side fitted with an endpoint for its normal
GHOST_STEP_M = 0.05  # march step of the mirror ray, m


def scan_normals(ex: F64, ey: F64, valid: npt.NDArray[np.bool_]) -> tuple[F64, F64, npt.NDArray[np.bool_]]:
    """(S, B) unit normals of the endpoints (any sign) and whether a neighbour supports
    each (False: an isolated point)."""
    r = np.hypot(ex, ey)
    gap = 0.25 + 0.25 * r
    s_n, b_n = ex.shape
    w = NORMAL_HALF_WINDOW
    acc = {k: np.zeros((s_n, b_n)) for k in ("n", "x", "y", "xx", "xy", "yy")}
    x0 = np.where(valid, ex, 0.0)
    y0 = np.where(valid, ey, 0.0)
    neighbours = np.zeros((s_n, b_n), np.int64)
    for o in range(-w, w + 1):
        lo, hi = max(0, -o), min(b_n, b_n - o)  # j in [lo, hi): j + o in range
        xs = np.zeros((s_n, b_n))
        ys = np.zeros((s_n, b_n))
        ok = np.zeros((s_n, b_n), bool)
        xs[:, lo:hi] = x0[:, lo + o:hi + o]
        ys[:, lo:hi] = y0[:, lo + o:hi + o]
        ok[:, lo:hi] = valid[:, lo + o:hi + o]
        ok &= valid & (np.hypot(xs - x0, ys - y0) <= gap)
        if o != 0:
            neighbours += ok
        dx, dy = np.where(ok, xs - x0, 0.0), np.where(ok, ys - y0, 0.0)  # centred on j
        acc["n"] += ok
        acc["x"] += dx
        acc["y"] += dy
        acc["xx"] += dx * dx
        acc["xy"] += dx * dy
        acc["yy"] += dy * dy
    n = np.maximum(acc["n"], 1.0)
    mx, my = acc["x"] / n, acc["y"] / n
    sxx = acc["xx"] / n - mx * mx
    sxy = acc["xy"] / n - mx * my
    syy = acc["yy"] / n - my * my
    psi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # direction of the surface
    return -np.sin(psi), np.cos(psi), neighbours > 0


def scan_fans(
    log: LaserLog, ring: SonarRing, physics: SonarPhysics, seed: int, scans: slice
) -> Fan:
    """The fans of every sonar of ``ring`` at the scans ``scans`` (rows scan-major)."""
    m = log.laser_mount
    valid = log.valid_returns()[scans]
    rng_ = log.ranges[scans]
    ang = log.angles[scans]
    r = np.where(valid, rng_, 0.0)
    th = np.where(valid, ang, 0.0) + m.yaw
    ex = m.x + r * np.cos(th)  # endpoints in the base frame
    ey = m.y + r * np.sin(th)
    nx, ny, supported = scan_normals(ex, ey, valid)
    # The building patch of every endpoint, hence its critical angle.
    bx, by, byaw = log.x[scans, None], log.y[scans, None], log.yaw[scans, None]
    c, s = np.cos(byaw), np.sin(byaw)
    wx, wy = bx + c * ex - s * ey, by + s * ex + c * ey
    crit = critical_angles(patch_keys(wx, wy, physics.surface_patch_m), physics, seed)

    s_n, b_n = ex.shape
    k_n = len(ring)
    dx = ex[:, None, :] - ring.x[None, :, None]  # (S, K, B)
    dy = ey[:, None, :] - ring.y[None, :, None]
    bearing = wrap_angle(np.arctan2(dy, dx) - ring.yaw[None, :, None])
    inside = valid[:, None, :] & (np.abs(bearing) <= physics.audible_half_angle())
    rays = max(1, int(inside.sum(axis=2).max()) if inside.size else 1)
    order = np.argsort(~inside, axis=2, kind="stable")[:, :, :rays]  # in-cone beams first

    def take(a: F64) -> F64:
        full = np.broadcast_to(a, (s_n, k_n, b_n)) if a.ndim == 3 else np.broadcast_to(
            a[:, None, :], (s_n, k_n, b_n))
        return np.take_along_axis(full, order, axis=2)

    ok = np.take_along_axis(inside, order, axis=2)
    d1 = np.hypot(take(dx), take(dy))
    ux, uy = take(dx) / np.maximum(d1, 1e-9), take(dy) / np.maximum(d1, 1e-9)
    n_x, n_y = take(nx), take(ny)
    sup = np.take_along_axis(np.broadcast_to(supported[:, None, :], (s_n, k_n, b_n)), order, axis=2)
    dot = ux * n_x + uy * n_y
    cos1 = np.where(sup, np.abs(dot), 1.0)
    crit1 = take(crit)
    # Mirror ray from each endpoint; its second surface from the scan's free space.
    mx_, my_ = ux - 2 * dot * n_x, uy - 2 * dot * n_y
    px, py = take(np.broadcast_to(ex, ex.shape)), take(np.broadcast_to(ey, ey.shape))
    scan_of = np.broadcast_to(np.arange(s_n)[:, None, None], ok.shape)
    need = ok & sup & (cos1 < np.cos(crit1))
    reach = ring.max_range[None, :, None] - d1
    d2 = np.full(ok.shape, np.inf)
    cos2 = np.ones(ok.shape)
    crit2 = np.zeros(ok.shape)
    idx = np.nonzero(need & (reach > GHOST_STEP_M))
    if idx[0].size:
        g = _march(
            log, scans, ex, ey, valid, px[idx], py[idx], mx_[idx], my_[idx], reach[idx],
            scan_of[idx],
        )
        hit_t, hit_b = g
        found = np.isfinite(hit_t)
        si = scan_of[idx][found]
        bi = hit_b[found]
        sel = tuple(a[found] for a in idx)
        d2[sel] = hit_t[found]
        gx, gy = mx_[sel], my_[sel]
        cos2[sel] = np.where(supported[si, bi], np.abs(gx * nx[si, bi] + gy * ny[si, bi]), 1.0)
        crit2[sel] = crit[si, bi]
    inf = np.inf
    shape = (s_n * k_n, rays)
    return Fan(
        off_axis=np.abs(np.take_along_axis(bearing, order, axis=2)).reshape(shape),
        d1=np.where(ok, d1, inf).reshape(shape),
        cos1=cos1.reshape(shape),
        crit1=crit1.reshape(shape),
        d2=d2.reshape(shape),
        cos2=cos2.reshape(shape),
        crit2=crit2.reshape(shape),
    )


def _march(
    log: LaserLog, scans: slice, ex: F64, ey: F64, valid: npt.NDArray[np.bool_],
    px: F64, py: F64, mx: F64, my: F64, reach: F64, scan: npt.NDArray[np.intp],
) -> tuple[F64, npt.NDArray[np.intp]]:
    """Distance along each mirror ray to where it leaves the scan's free space (+inf: it
    does not within ``reach`` or leaves the laser's view) and the laser beam there."""
    m = log.laser_mount
    ang = log.angles[scans]
    b_n = ang.shape[1]
    a0 = ang[:, 0]
    step_a = np.nanmedian(np.diff(ang, axis=1), axis=1)
    rng_ = log.ranges[scans]
    no_return = ~valid & np.isfinite(rng_) & (rng_ >= log.range_max[scans, None])
    wall = np.where(valid, rng_, np.where(no_return | np.isposinf(rng_), np.inf, np.nan))
    n = px.shape[0]
    t_hit = np.full(n, np.inf)
    b_hit = np.zeros(n, np.intp)
    live = np.arange(n)
    steps = int(np.ceil(float(reach.max()) / GHOST_STEP_M))
    for k in range(1, steps + 1):
        t = k * GHOST_STEP_M
        live = live[reach[live] >= t]
        if live.size == 0:
            break
        qx = px[live] + t * mx[live] - m.x
        qy = py[live] + t * my[live] - m.y
        rho = np.hypot(qx, qy)
        beta = wrap_angle(np.arctan2(qy, qx) - m.yaw)
        si = scan[live]
        b = np.rint((beta - a0[si]) / step_a[si]).astype(np.intp)
        inview = (b >= 0) & (b < b_n)
        bb = np.clip(b, 0, b_n - 1)
        w = wall[si, bb]
        unknown = ~inview | np.isnan(w)
        hit = ~unknown & (rho >= w)
        t_hit[live[hit]] = t
        b_hit[live[hit]] = bb[hit]
        live = live[~hit & ~unknown]
    return t_hit, b_hit


_CHUNK_RAYS = 1_000_000  # bound on (scan × sonar × beam) held at once


def scan_readings(
    log: LaserLog, ring: SonarRing, physics: SonarPhysics, seed: int
) -> tuple[F64, dict[str, int]]:
    """(S, K) readings (m) of the ring at every scan, and counts of ghosts, misses and
    crosstalk. Noise from ``PCG64(seed)``, drawn scan chunk by scan chunk in order."""
    from pipeline.tools.sonar.echo import readings

    rng = np.random.Generator(np.random.PCG64(seed))
    s_n, b_n = log.ranges.shape
    k_n = len(ring)
    out = np.empty((s_n, k_n))
    counts = {"ghost": 0, "missed": 0, "crosstalk": 0}
    step = max(1, _CHUNK_RAYS // max(1, k_n * b_n))
    for a in range(0, s_n, step):
        sl = slice(a, min(s_n, a + step))
        fan = scan_fans(log, ring, physics, seed, sl)
        n = sl.stop - sl.start
        lo = np.tile(ring.min_range, n)
        hi = np.tile(ring.max_range, n)
        e = readings(fan, lo, hi, physics, rng)
        out[sl] = e.range_m.reshape(n, k_n)
        counts["ghost"] += int(e.ghost.sum())
        counts["missed"] += int(e.missed.sum())
        counts["crosstalk"] += int(e.crosstalk.sum())
    return out, counts
