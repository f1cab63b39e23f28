"""The ``[sensors]`` section, interpreted in one place.

:func:`sensor_setup` turns the section into what the rest of sonarmap asks of it; nothing
else reads ``[sensors]``. Its precedence, per sensor name:

* **configured entry**: an explicit ``[[sensors.mounts]]`` entry of the name; else the
  ``[sensors] preset`` entry of the name; else none. An explicit entry replaces the preset's
  whole (it does not inherit the preset's limits).
* **beam limits** (fov, r_min, r_max), each on its own: the configured entry's non-zero
  value, which overrides the log (for sensors whose messages carry wrong metadata); else
  the value a reading carries; else the ``[sensors]`` default; else unknown (NaN).
* **mount**: an explicit entry; else the log's own static transform (``/tf_static``, a
  CSV ``sensors.csv``); else the preset entry; else, for a sensor whose frame *is* the base
  frame, the robot origin facing forward (decided by :func:`pipeline.stages.sensors.resolve_sensors`,
  which also has the log).
* **ring** (PointCloud / SonarArray messages carry no geometry: sonar i is the ring's i-th
  mount): the explicit ``[[sensors.mounts]]`` in file order when there are any, else the
  preset's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formats.arrays import F64
from formats.contract import SensorMount
from formats.options import MountConfig, SensorsConfig
from formats.presets import PRESETS

__all__ = ["BeamLimits", "ConfiguredSensor", "SensorRing", "SensorSetup", "sensor_setup"]

_DEG = math.pi / 180.0


@dataclass(frozen=True)
class BeamLimits:
    """Full beam width β (rad), r_min and r_max (m); NaN where not configured."""

    fov: float = math.nan
    min_range: float = math.nan
    max_range: float = math.nan

    def or_else(self, fallback: BeamLimits) -> BeamLimits:
        """Each unknown (NaN) value taken from ``fallback``."""
        return BeamLimits(
            *(
                mine if not math.isnan(mine) else other
                for mine, other in zip(self.as_tuple(), fallback.as_tuple(), strict=True)
            )
        )

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.fov, self.min_range, self.max_range)


@dataclass(frozen=True)
class ConfiguredSensor:
    """One sensor as the configuration describes it."""

    name: str
    mount: SensorMount  # metres, radians, in the base frame
    limits: BeamLimits  # the entry's own non-zero values; NaN elsewhere
    source: str  # "config" or "preset:<name>"


@dataclass(frozen=True)
class SensorRing:
    """Geometry of a sonar ring, one entry per sonar in ring order (m, rad): what a reader
    needs to decode PointCloud/SonarArray messages. Limits: entry, else ``[sensors]``
    default, else NaN."""

    names: tuple[str, ...]
    x: F64
    y: F64
    fov: F64
    min_range: F64
    max_range: F64
    origin: str  # where the mounts came from, for messages


@dataclass(frozen=True)
class SensorSetup:
    """``[sensors]`` interpreted (see the module docstring for the precedence)."""

    explicit: dict[str, ConfiguredSensor]
    preset: dict[str, ConfiguredSensor]
    preset_name: str
    defaults: BeamLimits
    ring_entries: tuple[ConfiguredSensor, ...]
    ring_origin: str
    ring_mounts: tuple[MountConfig, ...]  # the ring's entries as configured (0 = unset)

    def entry(self, name: str) -> ConfiguredSensor | None:
        """The configured entry of ``name``: explicit, else the preset's, else None."""
        return self.explicit.get(name) or self.preset.get(name)

    def configured_limits(self, name: str) -> BeamLimits:
        """The entry's limits, each unknown one from the ``[sensors]`` defaults."""
        entry = self.entry(name)
        own = entry.limits if entry is not None else BeamLimits()
        return own.or_else(self.defaults)

    def ring(self) -> SensorRing | None:
        """The ring geometry, or None when neither mounts nor a preset are configured."""
        if not self.ring_entries:
            return None
        limits = [self.configured_limits(e.name) for e in self.ring_entries]
        return SensorRing(
            names=tuple(e.name for e in self.ring_entries),
            x=np.array([e.mount.x for e in self.ring_entries], np.float64),
            y=np.array([e.mount.y for e in self.ring_entries], np.float64),
            fov=np.array([lim.fov for lim in limits], np.float64),
            min_range=np.array([lim.min_range for lim in limits], np.float64),
            max_range=np.array([lim.max_range for lim in limits], np.float64),
            origin=self.ring_origin,
        )


def sensor_setup(sensors: SensorsConfig) -> SensorSetup:
    """Interpret a ``[sensors]`` section (already validated by the config loader)."""
    explicit = {m.name: _configured(m, "config") for m in sensors.mounts}
    preset_mounts = PRESETS.get(sensors.preset, ()) if sensors.preset else ()
    preset = {m.name: _configured(m, f"preset:{sensors.preset}") for m in preset_mounts}
    if sensors.mounts:
        ring, origin = tuple(explicit[m.name] for m in sensors.mounts), "sensors.mounts"
        ring_mounts = tuple(sensors.mounts)
    else:
        ring, origin = tuple(preset.values()), f"preset '{sensors.preset}'"
        ring_mounts = tuple(preset_mounts)
    return SensorSetup(
        explicit=explicit,
        preset=preset,
        preset_name=sensors.preset,
        defaults=BeamLimits(
            _positive(sensors.fov_deg, _DEG), _positive(sensors.min_range), _positive(sensors.max_range)
        ),
        ring_entries=ring,
        ring_origin=origin,
        ring_mounts=ring_mounts,
    )


def _configured(m: MountConfig, source: str) -> ConfiguredSensor:
    return ConfiguredSensor(
        name=m.name,
        mount=SensorMount(m.x, m.y, math.radians(m.yaw_deg)),
        limits=BeamLimits(_positive(m.fov_deg, _DEG), _positive(m.min_range), _positive(m.max_range)),
        source=source,
    )


def _positive(value: float, scale: float = 1.0) -> float:
    """A configured value; 0 (the default) means "not configured" and becomes NaN."""
    return value * scale if value > 0 else math.nan
