"""The virtual sonar ring to emulate, and what of it the laser can see."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from formats.arrays import F64
from formats.contract import SensorMount
from formats.errors import ConfigError, InputError
from formats.laser_log import LaserLog
from formats.options import MountConfig
from formats.presets import PRESETS
from formats.sensor_config import sensor_setup
from pipeline.config import Config
from pipeline.tools.sonar_ring import SonarRing

DEFAULT_FOV_DEG = 30.0  # Polaroid 600-series beam, full width
DEFAULT_MAX_RANGE_M = 5.0
_COVERAGE_RAYS = 61  # directions sampled across a cone to measure how much the laser sees


def ring_from_mounts(
    mounts: Sequence[MountConfig],
    *,
    fov_deg: float | None = None,
    max_range: float | None = None,
    default_fov_deg: float = DEFAULT_FOV_DEG,
    default_min_range: float = 0.0,
    default_max_range: float = DEFAULT_MAX_RANGE_M,
) -> SonarRing:
    """The ring of ``mounts``; ``fov_deg``/``max_range`` override every sonar, mount values
    of 0 ("from the log") take the defaults."""
    if not mounts:
        raise ConfigError("no sonar mounts to emulate (give a preset or [[sensors.mounts]])")
    if fov_deg is not None and not 0 < fov_deg < 180:
        raise ConfigError(f"fov_deg must be in (0, 180), got {fov_deg!r}")
    if max_range is not None and not (max_range > 0 and math.isfinite(max_range)):
        raise ConfigError(f"max_range must be > 0, got {max_range!r}")
    return SonarRing.from_mounts([
        replace(
            m,
            fov_deg=fov_deg if fov_deg is not None else (m.fov_deg or default_fov_deg),
            min_range=m.min_range or default_min_range,
            max_range=max_range if max_range is not None else (m.max_range or default_max_range),
        )
        for m in mounts
    ])


def mounts_from_config(cfg: Config, preset: str | None = None) -> tuple[MountConfig, ...]:
    """Sonar mounts: ``preset`` if given, else ``[[sensors.mounts]]``, else the config's
    preset, else the Pioneer P3-DX ring."""
    if preset:
        if preset not in PRESETS:
            raise ConfigError(f"unknown preset '{preset}' (known: {', '.join(sorted(PRESETS))})")
        return PRESETS[preset]
    return sensor_setup(cfg.sensors).ring_mounts or PRESETS["pioneer-p3dx"]


def laser_view(log: LaserLog) -> tuple[float, float]:
    """The laser's field of view in its frame, ``(lo, hi)`` rad, half a beam either side."""
    a = log.angles
    finite = a[np.isfinite(a)]
    if finite.size == 0:
        raise InputError("laser scans have no beams")
    steps = np.diff(a, axis=1)
    steps = np.abs(steps[np.isfinite(steps) & (steps != 0)])
    half = 0.5 * float(np.median(steps)) if steps.size else 0.0
    return float(finite.min()) - half, float(finite.max()) + half


def cone_coverage(
    ring: SonarRing, mount: SensorMount, view: tuple[float, float]
) -> tuple[F64, npt.NDArray[np.bool_]]:
    """Per sonar: the fraction of its cone (sampled at its max range) inside the laser's
    view, and whether its axis (at max range) is inside."""
    lo, hi = view
    u = np.linspace(-0.5, 0.5, _COVERAGE_RAYS)
    # (K, R+1): R rays across the cone, then the axis.
    ang = ring.yaw[:, None] + np.concatenate(
        [u[None, :] * ring.fov[:, None], np.zeros((len(ring), 1))], axis=1
    )
    px = ring.x[:, None] + ring.max_range[:, None] * np.cos(ang) - mount.x
    py = ring.y[:, None] + ring.max_range[:, None] * np.sin(ang) - mount.y
    bearing = np.arctan2(py, px) - mount.yaw
    if hi - lo >= 2 * np.pi:
        inside = np.ones(bearing.shape, bool)
    else:
        inside = (bearing - lo) % (2 * np.pi) <= hi - lo
    return inside[:, :-1].mean(axis=1), inside[:, -1]
