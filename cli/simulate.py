"""``sonarmap simulate``: a seeded sonar log of a robot driving through a world."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

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
        specular_cutoff: Annotated[float, typer.Option(help="Incidence cut-off, degrees.")] = 60.0,
        p_miss: Annotated[float, typer.Option(help="Fraction of missed echoes.")] = 0.02,
        p_crosstalk: Annotated[float, typer.Option(help="Fraction of crosstalk readings.")] = 0.01,
        drift_xy: Annotated[float, typer.Option(help="Odometry position drift, m per √m.")] = 0.0,
        drift_yaw: Annotated[float, typer.Option(help="Odometry yaw drift, rad per √rad.")] = 0.0,
        drift_scale: Annotated[
            float, typer.Option(help="Odometry scale error, fraction (0.03: 3 % too long).")
        ] = 0.0,
        drift_heading_bias: Annotated[
            float, typer.Option(help="Odometry heading bias, degrees per metre driven.")
        ] = 0.0,
        drift_heading_walk: Annotated[
            float, typer.Option(help="Odometry heading random walk, rad per √m driven.")
        ] = 0.0,
        drift_slips: Annotated[float, typer.Option(help="Wheel slips per 100 m driven.")] = 0.0,
        drift_slip_yaw: Annotated[
            float, typer.Option(help="Std of one slip's heading error, degrees.")
        ] = 0.0,
        drift_slip_scale: Annotated[
            float, typer.Option(help="Std of one slip's scale error over 0.5 m, fraction.")
        ] = 0.0,
        drift_wheel_odometry: Annotated[
            bool, typer.Option(help="Set every --drift-* term left at 0 to typical "
                               "wheel-odometry figures (docs/POSE_REFINEMENT.md).")
        ] = False,
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

        cfg = load_config(config)
        mounts = cfg.sensors.mounts or PRESETS[cfg.sensors.preset or "pioneer-p3dx"]
        opts = SimOptions(
            seed=seed, speed=speed, pose_rate_hz=pose_rate, ring_rate_hz=ring_rate,
            specular_cutoff_deg=specular_cutoff, p_miss=p_miss, p_crosstalk=p_crosstalk,
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
