"""``sonarmap emulate``: a sonar log emulated from real laser scans (CARMEN or LaserScan)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from cli.drift_options import (
    DriftHeadingBias,
    DriftHeadingWalk,
    DriftScale,
    DriftSlips,
    DriftSlipScale,
    DriftSlipYaw,
    DriftWheelOdometry,
    DriftXY,
    DriftYaw,
)
from cli.errors import handle_errors
from formats.presets import PRESETS

_FORMATS = ("ros1", "ros2", "ros2-mcap", "mcap", "mcap-ros1", "csv", "csv-set")


def register(app: typer.Typer) -> None:
    """Add the ``emulate`` command to ``app``."""
    app.command("emulate")(emulate)


@handle_errors
def emulate(
    laser_log: Annotated[
        str,
        typer.Argument(
            help="CARMEN log (.log/.log.gz, FLASER) or ROS 1/ROS 2/MCAP log with "
            "sensor_msgs/LaserScan, or its URL (s3://, gs://, az://, http(s)://).",
            show_default=False,
        ),
    ],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Sonar log to write (must not exist).")
    ],
    format: Annotated[
        str, typer.Option("--format", "-f", help=f"Output format: {', '.join(_FORMATS)}.")
    ] = "mcap",
    preset: Annotated[
        str | None,
        typer.Option(
            "--preset",
            help=f"Sonar ring preset ({', '.join(PRESETS)}); default: the config's "
            "mounts, else pioneer-p3dx.",
        ),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(
            "--config",
            "-c",
            help="TOML configuration (sensors, grid, input sections).",
        ),
    ] = None,
    max_range: Annotated[
        float | None,
        typer.Option(
            "--max-range",
            help="Sonar max range for every sonar, m (default: the mounts', 5.0 for the Pioneer).",
        ),
    ] = None,
    fov_deg: Annotated[
        float | None,
        typer.Option(
            "--fov-deg",
            help="Sonar beam width for every sonar, degrees (default: "
            "the mounts', 30 for the Pioneer).",
        ),
    ] = None,
    resolution: Annotated[
        float | None,
        typer.Option(
            "--resolution",
            "-r",
            help="Cell size of the laser reference map, m (default: grid.resolution of the config, 0.05).",
        ),
    ] = None,
    full_cone: Annotated[
        bool,
        typer.Option(
            "--full-cone",
            help="Emit only sonars whose whole cone the laser sees "
            "(default: those whose beam axis it sees).",
        ),
    ] = False,
    max_scans: Annotated[
        int | None, typer.Option("--max-scans", min=1, help="Use only the first N scans.")
    ] = None,
    laser_topic: Annotated[
        str | None, typer.Option("--laser-topic", help="LaserScan topic (ROS logs).")
    ] = None,
    laser_max_range: Annotated[
        float | None,
        typer.Option(
            "--laser-max-range",
            help="CARMEN laser max, m: readings at or above are no return (default: PARAM "
            "robot_front_laser_max, else 81.83).",
        ),
    ] = None,
    compression: Annotated[
        str,
        typer.Option("--compression", help="Chunk compression: none; ros1 bz2/lz4; mcap lz4/zstd."),
    ] = "none",
    drift_scale: DriftScale = 0.0,
    drift_heading_bias: DriftHeadingBias = 0.0,
    drift_xy: DriftXY = 0.0,
    drift_yaw: DriftYaw = 0.0,
    drift_seed: Annotated[int, typer.Option("--drift-seed", help="Seed of the drift noise.")] = 0,
    drift_heading_walk: DriftHeadingWalk = 0.0,
    drift_slips: DriftSlips = 0.0,
    drift_slip_yaw: DriftSlipYaw = 0.0,
    drift_slip_scale: DriftSlipScale = 0.0,
    drift_wheel_odometry: DriftWheelOdometry = False,
    raw_odometry: Annotated[
        bool,
        typer.Option("--raw-odometry", help="Log the laser log's own wheel odometry (CARMEN "
                     "ODOM lines) as the robot's poses instead of the corrected scan poses: "
                     "real drift; the truth trajectory keeps the corrected poses."),
    ] = False,
    sonar_model: Annotated[
        str,
        typer.Option("--sonar-model", help="realistic: the sonar physics model (beam pattern, "
                     "specular loss per surface, multipath, misses, crosstalk, range noise; "
                     "docs/SONAR_PHYSICS.md); ideal: the shortest laser return in the cone."),
    ] = "realistic",
    sonar_param: Annotated[
        list[str] | None,
        typer.Option("--sonar-param", help="Override a realistic-model parameter, KEY=VALUE "
                     "(repeatable; keys and units in docs/SONAR_PHYSICS.md)."),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the realistic sonar's noise.")] = 0,
    firing_rate: Annotated[
        float | None,
        typer.Option("--firing-rate", help="Fire the whole ring at this many readings per "
                     "second (a Pioneer: about 25) into the laser map along the trajectory "
                     "interpolated between scans, every sonar of the ring (default: one "
                     "reading per sonar the laser sees per laser scan)."),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No summary.")] = False,
) -> None:
    """Emulate a sonar ring from real laser scans: by default each virtual sonar reads what
    the sonar physics model hears from the laser's surfaces in its beam (--sonar-model
    ideal: the shortest laser return inside its cone, its max range when none). Writes the sonar log, the
    laser occupancy map <stem>.laser.yaml/.pgm (the reference) and the trajectory
    <stem>.truth.csv beside it. Sonars outside the laser's view are not emitted.
    The --drift-* options drift the logged odometry (seeded; the truth trajectory keeps
    the poses before drift); --raw-odometry logs the robot's real odometry instead.

    Examples:

      sonarmap emulate sample_logs/intel-lab/intel-corrected.log.gz -o intel.mcap --compression zstd

      sonarmap emulate robot.bag -o sonar.bag --format ros1 --laser-topic /scan

      sonarmap emulate intel.log -o intel_csv --format csv-set --fov-deg 25 --max-range 4

      sonarmap emulate intel.log -o drifted.mcap --drift-scale 0.03 --drift-heading-bias 0.8

      sonarmap emulate intel.log -o odometry.mcap --raw-odometry

      sonarmap emulate intel.log -o walk.mcap --drift-heading-walk 0.01 --drift-scale -0.02

      sonarmap emulate intel.log -o ring.mcap --firing-rate 25 --preset pioneer-p3dx
    """
    from pipeline.config import load_config
    from pipeline.drift import DriftModel, drift_model
    from pipeline.tools.emulate import EmulateOptions, run_emulation
    from pipeline.tools.sonar import SonarPhysics, check_model_name

    if format not in _FORMATS:
        raise typer.BadParameter(f"must be one of {', '.join(_FORMATS)}", param_hint="--format")
    cfg = load_config(config)
    options = EmulateOptions(
        preset=preset,
        fov_deg=fov_deg,
        max_range=max_range,
        require_full_cone=full_cone,
        max_scans=max_scans,
        laser_topic=laser_topic,
        laser_max_range=laser_max_range,
        map_resolution=resolution,
        compression=compression,
        drift=drift_model(DriftModel(drift_scale, drift_heading_bias, drift_xy, drift_yaw,
                                     drift_heading_walk, drift_slips, drift_slip_yaw,
                                     drift_slip_scale), drift_wheel_odometry),
        drift_seed=drift_seed,
        raw_odometry=raw_odometry,
        sonar_model=check_model_name(sonar_model),
        physics=SonarPhysics().with_overrides(sonar_param or []),
        seed=seed,
        firing_rate_hz=firing_rate,
    )
    from cli.errors import location_argument
    from formats.storage.options import configure

    configure(cfg.storage)
    result = run_emulation(location_argument(laser_log), output, format, config=cfg,
                           options=options)
    if quiet:
        return
    for note in result.notes:
        typer.echo(f"note: {note}")
    h, w = result.map_shape
    typer.echo(
        f"emulated {result.readings} readings of {len(result.sonars)} sonars from "
        f"{result.scans} laser scans; laser map {w}×{h} cells"
    )
    for p in result.paths:
        typer.echo(f"wrote {p}")
