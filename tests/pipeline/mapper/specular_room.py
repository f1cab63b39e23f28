"""A specular sonar in the synthetic room (tests only): a wall answers a ray only within
``critical_deg`` of its normal; the reading is the nearest answering ray of the cone's fan,
else the sonar's maximum range (no echo)."""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.mapper.synthetic import ring_scans, room_segments
from pipeline.mapper.types import Scan

# The room of pipeline.mapper.synthetic with an oblique wall across one corner (30° off
# the x axis): the ring's loop passes it at an angle.
OBLIQUE = (0.0, 4.2, 2.6, 6.0)


def segments() -> np.ndarray:
    """The room's walls and the oblique wall, ``(S, 4)``: x0, y0, x1, y1, m."""
    return np.vstack([room_segments(), np.array([OBLIQUE])])


def _first_hits(ox, oy, theta, segs):  # type: ignore[no-untyped-def]
    """Distance to the first wall along each ray and the cosine of its incidence."""
    dx, dy = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x0, y0, x1, y1 = (segs[None, :, i] for i in range(4))
    ex, ey = x1 - x0, y1 - y0
    wx, wy = x0 - ox[:, None], y0 - oy[:, None]
    den = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / den
        u = (wx * dy - wy * dx) / den
    hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    t = np.where(hit, t, np.inf)
    k = np.argmin(t, axis=1)
    rows = np.arange(t.shape[0])
    length = np.hypot(ex[0, k], ey[0, k])
    cos_inc = np.abs(dx[:, 0] * ey[0, k] - dy[:, 0] * ex[0, k]) / length
    return t[rows, k], cos_inc


def specular_scans(n_scans: int, critical_deg: float | None, rays: int = 15) -> list[Scan]:
    """``ring_scans``' poses and cones in the room with the oblique wall, read again by a
    specular sonar (``critical_deg`` None: every wall answers at any incidence)."""
    scans = ring_scans(n_scans)
    segs = segments()
    out = []
    for s in scans:
        offsets = np.linspace(-0.5, 0.5, rays)[None, :] * s.fov[:, None]
        theta = (s.alpha[:, None] + offsets).ravel()
        d, cos_inc = _first_hits(np.repeat(s.origin_x, rays), np.repeat(s.origin_y, rays),
                                 theta, segs)
        if critical_deg is not None:
            d = np.where(cos_inc >= np.cos(np.radians(critical_deg)), d, np.inf)
        d = d.reshape(len(s), rays).min(axis=1)
        d = np.where(d >= s.max_range, s.max_range, d)
        out.append(dataclasses.replace(s, range_m=d))
    return out


def distance_to(segs: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distance of points to the nearest of ``segs``, m."""
    best = np.full(x.shape, np.inf)
    for x0, y0, x1, y1 in segs:
        ex, ey = x1 - x0, y1 - y0
        t = np.clip(((x - x0) * ex + (y - y0) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
        best = np.minimum(best, np.hypot(x - (x0 + t * ex), y - (y0 + t * ey)))
    return best
