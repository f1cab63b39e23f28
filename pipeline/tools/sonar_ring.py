"""A ring of sonars as arrays: the one geometry ``simulate`` and ``emulate`` fire from."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.arrays import F64
from formats.errors import ConfigError
from formats.options import MountConfig

__all__ = ["SonarRing"]


@dataclass(frozen=True)
class SonarRing:
    """Sonars in the base frame, one entry each: position (m), axis and full beam width β
    (rad), range limits (m)."""

    names: tuple[str, ...]
    x: F64
    y: F64
    yaw: F64
    fov: F64
    min_range: F64
    max_range: F64

    def __len__(self) -> int:
        return len(self.names)

    def take(self, index: npt.NDArray[np.intp]) -> SonarRing:
        """The sonars at ``index``, in that order."""
        return SonarRing(
            tuple(self.names[i] for i in index.tolist()),
            self.x[index],
            self.y[index],
            self.yaw[index],
            self.fov[index],
            self.min_range[index],
            self.max_range[index],
        )

    @staticmethod
    def from_mounts(mounts: Sequence[MountConfig]) -> SonarRing:
        """The ring of fully specified mounts (degrees → radians). ConfigError when there
        are none, a name is empty or repeated, a beam width is not in (0°, 180°) or the
        range limits are not ``0 <= min < max < inf``."""
        if not mounts:
            raise ConfigError("the sonar ring has no mounts")
        names = [m.name for m in mounts]
        if len(set(names)) != len(names) or not all(names):
            raise ConfigError(f"sonar mount names must be unique and non-empty, got {names}")
        for m in mounts:
            if not 0 < m.fov_deg < 180:
                raise ConfigError(f"sonar {m.name}: beam width {m.fov_deg}° is not in (0°, 180°)")
            if not (0 <= m.min_range < m.max_range and math.isfinite(m.max_range)):
                raise ConfigError(
                    f"sonar {m.name}: min range {m.min_range} m is not below max range "
                    f"{m.max_range} m"
                )

        def col(attr: str) -> F64:
            return np.array([float(getattr(m, attr)) for m in mounts], dtype=np.float64)

        return SonarRing(
            names=tuple(names),
            x=col("x"),
            y=col("y"),
            yaw=np.deg2rad(col("yaw_deg")),
            fov=np.deg2rad(col("fov_deg")),
            min_range=col("min_range"),
            max_range=col("max_range"),
        )
