"""A synthetic sonar world for tests and benchmarks: a room, a sonar ring, ray casting.

Deterministic for a given seed. The room is a rectangle ``[0, 8] × [0, 6]`` m with a
free-standing box and a pillar; a 16-sonar ring (the Pioneer P3-DX layout, β = 30°,
0.1-5 m) drives an elliptical loop and fires all 16 sonars once per scan. A sonar returns
the shortest range among rays fanned across its cone (the first echo), plus Gaussian noise;
no echo within ``r_max`` gives the sensor's maximum value ``r_max`` (a "no echo" reading).
"""

from __future__ import annotations

import math

import numpy as np

from formats.presets import PRESETS
from pipeline.mapper.types import F64, GridSpec, Scan


def room_segments() -> F64:
    """Wall segments ``(S, 4)``: x0, y0, x1, y1, m."""
    def box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float, float, float]]:
        return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]

    segs = box(0.0, 0.0, 8.0, 6.0) + box(3.4, 2.6, 4.6, 3.4) + box(6.6, 0.8, 6.9, 1.1)
    return np.array(segs, dtype=np.float64)


def room_grid(resolution: float = 0.05) -> GridSpec:
    """A grid covering the room with a 0.5 m margin."""
    return GridSpec.covering(-0.5, -0.5, 8.5, 6.5, resolution)


def cast_rays(ox: F64, oy: F64, theta: F64, segments: F64) -> F64:
    """Distance along each ray to the first segment it hits, m (inf where none)."""
    dx, dy = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x0, y0, x1, y1 = (segments[None, :, i] for i in range(4))
    ex, ey = x1 - x0, y1 - y0
    wx, wy = x0 - ox[:, None], y0 - oy[:, None]
    den = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / den  # along the ray
        u = (wx * dy - wy * dx) / den  # along the segment
    hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    return np.where(hit, t, np.inf).min(axis=1)


def ring_scans(
    n_scans: int,
    seed: int = 0,
    noise_m: float = 0.01,
    rays_per_cone: int = 7,
    step_m: float = 0.04,
    max_range: float = 5.0,
    sweep: int = 1,
) -> list[Scan]:
    """``n_scans`` scans of the 16-sonar ring driving an elliptical loop in the room.

    ``sweep > 1`` makes each scan a stop-and-scan sweep: the ring fires ``sweep`` times from
    the same position, turned by ``20°/sweep`` between firings (a denser fan of cones, as
    from a rotating sonar); the scan then has ``16·sweep`` readings.
    """
    rng = np.random.Generator(np.random.PCG64(seed))
    mounts = PRESETS["pioneer-p3dx"]
    turns = np.radians(20.0 / sweep) * np.arange(sweep)
    # A sweep turns the whole ring about the robot centre.
    base_x = np.array([m.x for m in mounts])
    base_y = np.array([m.y for m in mounts])
    base_yaw = np.radians([m.yaw_deg for m in mounts])
    ct, st = np.cos(turns)[:, None], np.sin(turns)[:, None]
    mx = (ct * base_x - st * base_y).ravel()
    my = (st * base_x + ct * base_y).ravel()
    myaw = (base_yaw + turns[:, None]).ravel()
    fov = math.radians(30.0)
    r_min, r_max = 0.1, max_range
    segs = room_segments()
    ax, ay, cx, cy = 2.6, 1.7, 4.0, 3.0  # the loop: an ellipse around the box
    perimeter = math.pi * (3 * (ax + ay) - math.sqrt((3 * ax + ay) * (ax + 3 * ay)))
    s = np.arange(n_scans) * (2 * math.pi * step_m / perimeter)
    px, py = cx + ax * np.cos(s), cy + ay * np.sin(s)
    yaw = np.arctan2(ay * np.cos(s), -ax * np.sin(s))  # tangent to the loop
    offsets = np.linspace(-0.5 * fov, 0.5 * fov, rays_per_cone)
    k = mx.shape[0]
    # All sonar origins and axes of all scans at once.
    c, sn = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    ox = px[:, None] + c * mx - sn * my
    oy = py[:, None] + sn * mx + c * my
    alpha = yaw[:, None] + myaw
    theta = alpha[:, :, None] + offsets
    d = cast_rays(
        np.repeat(ox.ravel(), rays_per_cone),
        np.repeat(oy.ravel(), rays_per_cone),
        theta.ravel(),
        segs,
    ).reshape(n_scans, k, rays_per_cone).min(axis=2)
    d = d + noise_m * rng.standard_normal(d.shape)
    d = np.where(d >= r_max, r_max, np.maximum(d, 0.0))
    t0 = 1_000_000_000
    scans = []
    for i in range(n_scans):
        t = np.full(k, t0 + i * 100_000_000, dtype=np.int64)
        scans.append(
            Scan(
                t_ns=t,
                sensor_id=np.arange(k, dtype=np.int32),
                range_m=d[i].copy(),
                origin_x=ox[i].copy(),
                origin_y=oy[i].copy(),
                alpha=alpha[i].copy(),
                fov=np.full(k, fov),
                min_range=np.full(k, r_min),
                max_range=np.full(k, r_max),
            )
        )
    return scans
