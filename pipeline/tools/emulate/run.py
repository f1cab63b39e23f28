"""``sonarmap emulate``: read the laser log, emulate the ring, write the sonar log with the
laser map and the trajectory beside it."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from formats.errors import ConfigError, InputError, OutputError
from formats.storage.location import Location
from pipeline.config import Config
from pipeline.drift import DriftModel
from pipeline.tools.emulate.emulation import Emulation, emulate
from pipeline.tools.emulate.laser_input import load_laser_log
from pipeline.tools.emulate.laser_map import LaserMap, LaserMapOptions, laser_occupancy_map
from pipeline.tools.emulate.ring import (
    DEFAULT_FOV_DEG,
    DEFAULT_MAX_RANGE_M,
    mounts_from_config,
    ring_from_mounts,
)
from pipeline.tools.log_with_reference import reference_paths, write_log_with_reference
from pipeline.tools.sonar.model import SonarPhysics, check_model_name


def output_paths(out_path: Path) -> tuple[Path, Path, Path]:
    """``<stem>.laser.yaml``, ``<stem>.laser.pgm`` and ``<stem>.truth.csv`` beside a log."""
    return reference_paths(out_path, "laser")


def write_emulation(
    em: Emulation,
    laser_map: LaserMap,
    out_path: str | Path,
    fmt: str,
    *,
    compression: str = "none",
) -> list[Path]:
    """Write the sonar log, the laser map and the trajectory (the true poses: those before
    drift when the odometry is drifted); return the paths (log first).

    Refuses (OutputError) when any of them exists already, before writing anything.
    """
    truth = em.truth if em.truth is not None else em.content.poses
    return write_log_with_reference(
        em.content, out_path, fmt, compression=compression, kind="laser",
        probability=laser_map.probability, grid=laser_map.grid, trajectory=truth,
    )


@dataclass(frozen=True)
class EmulateOptions:
    """Options of :func:`run_emulation` (None = from the mounts / the configuration)."""

    preset: str | None = None
    fov_deg: float | None = None
    max_range: float | None = None
    require_full_cone: bool = False
    max_scans: int | None = None
    laser_topic: str | None = None
    laser_max_range: float | None = None
    map_resolution: float | None = None  # default: [grid] resolution of the config
    max_free_range: float = 30.0
    compression: str = "none"
    drift: DriftModel = field(default_factory=DriftModel)  # odometry drift (pipeline.drift)
    drift_seed: int = 0
    raw_odometry: bool = False  # log the laser log's own wheel odometry (real drift)
    sonar_model: str = "realistic"  # realistic | ideal (pipeline.tools.sonar)
    physics: SonarPhysics = field(default_factory=SonarPhysics)  # of the realistic model
    seed: int = 0  # of the realistic model's noise


@dataclass(frozen=True)
class EmulationResult:
    """What :func:`run_emulation` wrote and found."""

    paths: list[Path]
    scans: int
    readings: int
    sonars: tuple[str, ...]
    notes: tuple[str, ...] = field(default_factory=tuple)
    map_shape: tuple[int, int] = (0, 0)


def run_emulation(
    laser_path: str | Location,
    out_path: str | Path,
    fmt: str = "mcap",
    *,
    config: Config | None = None,
    options: EmulateOptions | None = None,
) -> EmulationResult:
    """The ``sonarmap emulate`` command: read the laser log, emulate the ring, write."""
    cfg = config if config is not None else Config()
    opt = options if options is not None else EmulateOptions()
    out = Path(out_path)
    if opt.raw_odometry and not opt.drift.is_zero:
        raise ConfigError("raw odometry and a drift model are exclusive: the raw odometry "
                          "drifts by itself")
    # Refuse existing outputs before the (slow) reading and emulation.
    for q in (out, *output_paths(out)):
        if q.exists() or q.is_symlink():
            raise OutputError("exists already, not overwriting", q)
    ring = ring_from_mounts(
        mounts_from_config(cfg, opt.preset),
        fov_deg=opt.fov_deg,
        max_range=opt.max_range,
        default_fov_deg=cfg.sensors.fov_deg or DEFAULT_FOV_DEG,
        default_min_range=cfg.sensors.min_range,
        default_max_range=cfg.sensors.max_range or DEFAULT_MAX_RANGE_M,
    )
    log = load_laser_log(
        laser_path,
        cfg,
        max_scans=opt.max_scans,
        laser_topic=opt.laser_topic,
        laser_max_range=opt.laser_max_range,
    )
    physics = opt.physics.validate() if check_model_name(opt.sonar_model) == "realistic" else None
    em = emulate(log, ring, require_full_cone=opt.require_full_cone, physics=physics,
                 seed=opt.seed)
    if opt.raw_odometry:
        if log.odometry is None:
            raise InputError("the log has no raw odometry apart from its scan poses (CARMEN "
                             "ODOM lines on the scans' clock)", laser_path)
        try:
            em = em.with_raw_odometry(log.odometry)
        except InputError as err:
            raise InputError(err.reason, laser_path) from None
    em = em.with_drift(opt.drift, opt.drift_seed)
    lmap = laser_occupancy_map(
        log,
        LaserMapOptions(
            resolution=opt.map_resolution or cfg.grid.resolution,
            max_free_range=opt.max_free_range,
            max_cells=cfg.grid.max_cells,
        ),
    )
    paths = write_emulation(em, lmap, out, fmt, compression=opt.compression)
    return EmulationResult(
        paths=paths,
        scans=len(log),
        readings=len(em.content.ranges),
        sonars=em.ring.names,
        notes=em.notes,
        map_shape=lmap.grid.shape,
    )
