"""A sonar ring and its physics: firing order, cone ray casting, specular loss, noise.

Geometry is in the world frame (m, rad). A reading casts a fan of rays across its cone
(about 1° apart); each ray stops at the first surface it meets and returns an echo only
when its incidence angle (between the ray and the surface normal) is below the specular
cut-off; otherwise it is reflected away and lost. The reading is the closest echo of the
fan; a reading with no echo inside ``r_max`` reports exactly ``r_max`` (as real drivers
do; the mapper's ``eps_max`` classifies it as no echo).
"""

from __future__ import annotations

import math

import numpy as np

from formats.arrays import F64, I32, I64
from formats.errors import ConfigError
from pipeline.tools.simulate.world import World, circle_distances, segment_distances

# Upper bound on ray×obstacle pairs evaluated at once (memory ≈ 8 B × a few arrays each).
_MAX_PAIRS = 1 << 21


def firing_schedule(
    n_sensors: int, ring_rate_hz: float, start_ns: int, end_ns: int
) -> tuple[I64, I32]:
    """Reading times (ns) and sensor indices: ring order, one sonar every 1/(rate·n) s,
    from ``start_ns`` up to and including ``end_ns``."""
    if not ring_rate_hz > 0:
        raise ConfigError(f"ring_rate_hz must be > 0, got {ring_rate_hz!r}")
    period_ns = 1e9 / (ring_rate_hz * n_sensors)
    count = int((end_ns - start_ns) // period_ns) + 1
    k = np.arange(count, dtype=np.int64)
    t = np.int64(start_ns) + np.round(k * period_ns).astype(np.int64)
    t = t[t <= end_ns]
    sensor = (np.arange(t.shape[0], dtype=np.int64) % n_sensors).astype(np.int32)
    return t, sensor


def cast_rays(world: World, ox: F64, oy: F64, theta: F64) -> tuple[F64, F64]:
    """First hit of each ray: distance (m, +inf when none) and |cos| of its incidence angle.

    ``ox, oy, theta`` are 1-D arrays of equal length (ray origins, m; directions, rad).
    Vectorised over rays × obstacles.
    """
    ux, uy = np.cos(theta), np.sin(theta)
    best = np.full(ox.shape, np.inf)
    cos_inc = np.zeros(ox.shape)
    seg = world.segments
    if seg.shape[0]:
        ax, ay = seg[None, :, 0], seg[None, :, 1]
        ex, ey = seg[None, :, 2] - ax, seg[None, :, 3] - ay
        elen = np.hypot(ex, ey)
        t = segment_distances(seg, ox, oy, ux, uy)
        j = np.argmin(t, axis=1)
        rows = np.arange(t.shape[0])
        best = t[rows, j]
        # cos(incidence) = |u · n| with n the unit normal of the segment = |u × e| / |e|.
        cos_inc = np.abs(ux * ey[0, j] - uy * ex[0, j]) / elen[0, j]
    cir = world.circles
    if cir.shape[0]:
        t, root = circle_distances(cir, ox, oy, ux, uy)
        j = np.argmin(t, axis=1)
        rows = np.arange(t.shape[0])
        tc = t[rows, j]
        # The normal at the hit is radial: |u · (p − c)| / r = sqrt(disc) / r.
        cc = root[rows, j] / cir[j, 2]
        closer = tc < best
        best = np.where(closer, tc, best)
        cos_inc = np.where(closer, cc, cos_inc)
    return best, cos_inc


def true_ranges(
    world: World,
    ox: F64,
    oy: F64,
    alpha: F64,
    fov: F64,
    max_range: F64,
    *,
    ray_step_rad: float = math.radians(1.0),
    specular_cutoff_rad: float = math.radians(60.0),
) -> F64:
    """Noise-free range per reading (m): the closest specular-valid echo in its cone, or
    ``+inf`` when no ray of the fan returns an echo within ``max_range``.

    ``ox, oy`` sonar origin (m), ``alpha`` beam axis (rad), ``fov`` full beam width (rad).
    """
    n = ox.shape[0]
    out = np.full(n, np.inf)
    if n == 0:
        return out
    k = max(2, math.ceil(float(fov.max()) / ray_step_rad) + 1)
    frac = np.linspace(-0.5, 0.5, k)
    cos_cut = math.cos(specular_cutoff_rad)
    reach = float(max_range.max())
    n_obst = max(1, world.segments.shape[0] + world.circles.shape[0])
    chunk = max(1, _MAX_PAIRS // (k * n_obst))
    for lo in range(0, n, chunk):
        sl = slice(lo, min(n, lo + chunk))
        sub = _nearby(world, ox[sl], oy[sl], reach)
        theta = alpha[sl, None] + fov[sl, None] * frac[None, :]
        rx = np.repeat(ox[sl], k)
        ry = np.repeat(oy[sl], k)
        dist, ci = cast_rays(sub, rx, ry, theta.reshape(-1))
        echo = np.where(ci >= cos_cut, dist, np.inf).reshape(-1, k)
        d = echo.min(axis=1)
        out[sl] = np.where(d < max_range[sl], d, np.inf)
    return out


def _nearby(world: World, ox: F64, oy: F64, reach: float) -> World:
    """The obstacles that can be within ``reach`` of any of the origins (bounding boxes)."""
    x0, x1 = float(ox.min()) - reach, float(ox.max()) + reach
    y0, y1 = float(oy.min()) - reach, float(oy.max()) + reach
    s = world.segments
    keep = (
        (np.maximum(s[:, 0], s[:, 2]) >= x0)
        & (np.minimum(s[:, 0], s[:, 2]) <= x1)
        & (np.maximum(s[:, 1], s[:, 3]) >= y0)
        & (np.minimum(s[:, 1], s[:, 3]) <= y1)
    )
    c = world.circles
    keep_c = (
        (c[:, 0] + c[:, 2] >= x0)
        & (c[:, 0] - c[:, 2] <= x1)
        & (c[:, 1] + c[:, 2] >= y0)
        & (c[:, 1] - c[:, 2] <= y1)
    )
    return World(s[keep], c[keep_c], name=world.name, bounds=world.bounds)


def add_sensor_errors(
    d_true: F64,
    min_range: F64,
    max_range: F64,
    rng: np.random.Generator,
    *,
    sigma_d0: float,
    k_d: float,
    p_miss: float,
    p_crosstalk: float,
) -> F64:
    """Measured ranges (m) from noise-free ones, rounded to float32 (what Range carries).

    Echoes get N(0, σ(d)) noise, σ(d) = σ_d0 + k_d·d, clipped to [r_min, r_max]; echoes
    closer than r_min read −inf (REP 117 "too close"); no echo reads exactly r_max. A
    fraction ``p_miss`` of readings miss their echo (r_max) and ``p_crosstalk`` read a
    random short range, uniform in [r_min, d). The draws are made for every reading in a
    fixed order, so the random stream does not depend on the geometry.
    """
    n = d_true.shape[0]
    z = rng.standard_normal(n)
    u_miss = rng.random(n)
    u_cross = rng.random(n)
    u_val = rng.random(n)
    echo = np.isfinite(d_true)
    d_safe = np.where(echo, d_true, 0.0)
    noisy = np.clip(d_safe + z * (sigma_d0 + k_d * d_safe), min_range, max_range)
    d = np.where(echo, noisy, max_range)
    d = np.where(echo & (d_true < min_range), -np.inf, d)
    d = np.where(u_miss < p_miss, max_range, d)
    cross = (u_cross < p_crosstalk) & np.isfinite(d)
    d = np.where(cross, min_range + u_val * (d - min_range), d)
    return d.astype(np.float32).astype(np.float64)
