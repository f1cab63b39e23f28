"""Sensor resolution: each sonar's mount and beam limits, from the configuration and the log.

The precedence is the one of :mod:`formats.sensor_config` (the one reading of
``[sensors]``, documented there and in the README); this module applies it to the sensors a
log has and the static mounts it carries. A sensor with readings and no mount is an
:class:`~formats.errors.InputError`: a map built with a guessed geometry would be wrong.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.arrays import F64
from formats.contract import RangeBatch, SensorMount
from formats.errors import InputError
from formats.options import FOV_MAX_DEG, FOV_MIN_DEG
from formats.ranges import LIMIT_M
from formats.sensor_config import sensor_setup
from pipeline.config import Config


@dataclass(frozen=True)
class SensorTable:
    """Per sensor id: mount (m, rad), where it came from, and beam-limit overrides (NaN = none)."""

    names: tuple[str, ...]
    mount_x: F64
    mount_y: F64
    mount_yaw: F64
    source: tuple[str, ...]
    fov_override: F64
    min_override: F64
    max_override: F64
    default_fov: float
    default_min: float
    default_max: float

    def apply_limits(self, batch: RangeBatch) -> tuple[F64, F64, F64]:
        """fov, r_min, r_max per reading after overrides and defaults."""
        sid = batch.sensor_id
        fov = _pick(self.fov_override[sid], batch.fov_rad, self.default_fov)
        lo = _pick(self.min_override[sid], batch.min_range_m, self.default_min)
        # A logged r_max that is not > 0 is none (sensor_msgs/Range: invalid): the default.
        with np.errstate(invalid="ignore"):
            logged_max = np.where(batch.max_range_m > 0, batch.max_range_m, np.nan)
        hi = _pick(self.max_override[sid], logged_max, self.default_max)
        return fov, lo, hi


def beam_problem(
    names: Sequence[str], sensor_id: npt.NDArray[np.int32], fov: F64, lo: F64, hi: F64
) -> str | None:
    """Why the resolved beam widths / limits of these readings cannot be mapped, naming
    the sensor, the value and the fix; None when they can. NaN fov is "none" (reported by
    the caller); limits that are NaN or <= 0 mean "no limit" (reading_quality)."""
    lo_fov, hi_fov = math.radians(FOV_MIN_DEG), math.radians(FOV_MAX_DEG)
    with np.errstate(invalid="ignore"):
        bad_fov = ~np.isnan(fov) & ~((fov >= lo_fov) & (fov < hi_fov))
        bad_lim = (lo > 0) & (hi > 0) & np.isfinite(lo) & ~(hi > lo)
        # A finite limit beyond a sonar's reach is a garbage value, not a limit.
        far = (np.isfinite(hi) & (hi > LIMIT_M.hi)) | (np.isfinite(lo) & (lo > LIMIT_M.hi))
    if far.any():
        i = int(np.flatnonzero(far)[0])
        return (
            f"sensor {names[int(sensor_id[i])]}: range limits {float(lo[i])!r}-{float(hi[i])!r}"
            f" m are beyond a sonar's reach ({LIMIT_M.hi:g} m; {int(far.sum())} readings);"
            " set min_range and max_range for it in [[sensors.mounts]]"
        )
    if bad_fov.any():
        i = int(np.flatnonzero(bad_fov)[0])
        return (
            f"sensor {names[int(sensor_id[i])]}: beam width (fov) {float(fov[i])!r} rad is "
            f"not in [{FOV_MIN_DEG:g}°, {FOV_MAX_DEG:g}°) ({int(bad_fov.sum())} readings); "
            "set fov_deg for it in [[sensors.mounts]]"
        )
    if bad_lim.any():
        i = int(np.flatnonzero(bad_lim)[0])
        return (
            f"sensor {names[int(sensor_id[i])]}: max_range {float(hi[i])!r} m is not above "
            f"min_range {float(lo[i])!r} m ({int(bad_lim.sum())} readings); set min_range "
            "and max_range for it in [[sensors.mounts]]"
        )
    return None


def _pick(override: F64, logged: F64, default: float) -> F64:
    out = np.where(np.isnan(override), logged, override)
    return np.where(np.isnan(out), default, out)


def resolve_sensors(
    sensor_names: Sequence[str],
    log_mounts: Mapping[str, SensorMount],
    config: Config,
    *,
    used: Sequence[bool] | None = None,
) -> SensorTable:
    """Resolve mounts and limits for every sensor id. ``used`` marks sensors that have
    readings; only those must have a mount."""
    setup = sensor_setup(config.sensors)
    base = config.input.base_frame
    n = len(sensor_names)
    mx, my, myaw = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    fov_o, min_o, max_o = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    sources: list[str] = []
    missing: list[str] = []
    for i, name in enumerate(sensor_names):
        entry = setup.entry(name)
        m: SensorMount | None
        if name in setup.explicit:
            m, src = setup.explicit[name].mount, "config"
        elif name in log_mounts:
            m, src = log_mounts[name], "log"
        elif name in setup.preset:
            m, src = setup.preset[name].mount, f"preset:{setup.preset_name}"
        elif name == base or name.lstrip("/") == base:
            m, src = SensorMount(0.0, 0.0, 0.0), "base_frame"
        else:
            m, src = None, "missing"
            if used is None or used[i]:
                missing.append(name)
        if m is not None:
            mx[i], my[i], myaw[i] = m.x, m.y, m.yaw
        if entry is not None:
            fov_o[i], min_o[i], max_o[i] = entry.limits.as_tuple()
        sources.append(src)
    if missing:
        shown = ", ".join(missing[:6]) + (" ..." if len(missing) > 6 else "")
        raise InputError(
            f"no mount for range sensor(s) {shown}: the log has no base_link→sensor transform; "
            f"add [[sensors.mounts]] entries or a [sensors] preset to the config"
        )
    return SensorTable(
        names=tuple(sensor_names),
        mount_x=mx,
        mount_y=my,
        mount_yaw=myaw,
        source=tuple(sources),
        fov_override=fov_o,
        min_override=min_o,
        max_override=max_o,
        default_fov=setup.defaults.fov,
        default_min=setup.defaults.min_range,
        default_max=setup.defaults.max_range,
    )
