"""``sonarmap simulate``: a seeded sonar log of a robot driving through a world."""

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


def register(app: typer.Typer) -> None:
    """Add the ``simulate`` command to ``app``."""

    @app.command()
    @handle_errors
    def simulate(
        world: Annotated[Path, typer.Argument(help="World file (.toml) or nav2 map (.yaml).")],
        output: Annotated[Path, typer.Option("--output", "-o", help="Log to write (must not exist).")],
        format: Annotated[
            str,
            typer.Option("--format", "-f", help="mcap, ros1, ros2, ros2-mcap, mcap-ros1, csv, csv-set."),
        ] = "mcap",
        waypoints: Annotated[
            Path | None,
            typer.Option("--waypoints", "-w", help="Waypoints CSV (x,y); default <world>.waypoints.csv."),
        ] = None,
        config: Annotated[
            Path | None,
            typer.Option("--config", "-c", help="Config whose [sensors] mounts/preset define the ring."),
        ] = None,
        seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
        speed: Annotated[float, typer.Option(help="Robot speed, m/s.")] = 0.3,
        pose_rate: Annotated[float, typer.Option(help="Odometry rate, Hz.")] = 20.0,
        ring_rate: Annotated[float, typer.Option(help="Full sonar ring revolutions per second.")] = 10.0,
        sonar_model: Annotated[
            str,
            typer.Option(help="realistic: the sonar physics model (docs/SONAR_PHYSICS.md); "
                         "ideal: the closest echo under one specular cut-off."),
        ] = "realistic",
        sonar_param: Annotated[
            list[str] | None,
            typer.Option(help="Override a realistic-model parameter, KEY=VALUE (repeatable; "
                         "keys and units in docs/SONAR_PHYSICS.md)."),
        ] = None,
        specular_cutoff: Annotated[
            float, typer.Option(help="Ideal model: incidence cut-off, degrees.")
        ] = 60.0,
        p_miss: Annotated[
            float | None,
            typer.Option(help="Fraction of missed echoes (default: 0.02 ideal, 0.03 realistic)."),
        ] = None,
        p_crosstalk: Annotated[
            float | None,
            typer.Option(help="Fraction of crosstalk readings (default: 0.01 ideal, 0.02 "
                         "realistic)."),
        ] = None,
        drift_xy: DriftXY = 0.0,
        drift_yaw: DriftYaw = 0.0,
        drift_scale: DriftScale = 0.0,
        drift_heading_bias: DriftHeadingBias = 0.0,
        drift_heading_walk: DriftHeadingWalk = 0.0,
        drift_slips: DriftSlips = 0.0,
        drift_slip_yaw: DriftSlipYaw = 0.0,
        drift_slip_scale: DriftSlipScale = 0.0,
        drift_wheel_odometry: DriftWheelOdometry = False,
        compression: Annotated[str, typer.Option(help="ros1: none/bz2/lz4; mcap: none/lz4/zstd.")] = "none",
    ) -> None:
        """Simulate a sonar ring on a robot driving through WORLD; write the log plus its
        ground truth (<stem>.truth.yaml/.pgm nav2 map, <stem>.truth.csv trajectory).
        The --drift-* options give the logged odometry a seeded error (scale, heading
        bias per metre, noise per step); the truth trajectory stays the true one.

        Examples:

          sonarmap simulate sample_logs/worlds/office.toml -o office.mcap

          sonarmap simulate sample_logs/worlds/orchard.toml -o orchard.bag -f ros1 --drift-xy 0.02

          sonarmap simulate sample_logs/worlds/office.toml -o drifted.mcap --drift-scale 0.03 --drift-heading-bias 0.8
        """
        from formats.presets import PRESETS
        from pipeline.config import load_config
        from pipeline.drift import drift_model
        from pipeline.tools.simulate.simulate import SimOptions, run_simulation
        from pipeline.tools.sonar import SonarPhysics, check_model_name

        cfg = load_config(config)
        mounts = cfg.sensors.mounts or PRESETS[cfg.sensors.preset or "pioneer-p3dx"]
        physics = SonarPhysics().with_overrides(
            [*(sonar_param or []),
             *([f"p_miss={p_miss}"] if p_miss is not None else []),
             *([f"p_crosstalk={p_crosstalk}"] if p_crosstalk is not None else [])]
        )
        opts = SimOptions(
            seed=seed, speed=speed, pose_rate_hz=pose_rate, ring_rate_hz=ring_rate,
            specular_cutoff_deg=specular_cutoff,
            p_miss=0.02 if p_miss is None else p_miss,
            p_crosstalk=0.01 if p_crosstalk is None else p_crosstalk,
            sonar_model=check_model_name(sonar_model), physics=physics,
            drift_xy=drift_xy, drift_yaw=drift_yaw, drift_scale=drift_scale,
            drift_heading_bias_deg_per_m=drift_heading_bias, mounts=mounts,
            drift_heading_walk=drift_heading_walk, drift_slips_per_100m=drift_slips,
            drift_slip_yaw_deg=drift_slip_yaw, drift_slip_scale=drift_slip_scale,
        )
        if drift_wheel_odometry:
            opts = opts.with_drift(drift_model(opts.drift, True))
        opts = opts.validate()
        paths = run_simulation(world, output, format, waypoints_path=waypoints, options=opts,
                               compression=compression)
        for p in paths:
            typer.echo(str(p))
