"""``sonarmap evaluate`` (a run against ground truth) and ``sonarmap regress`` (a run
against a golden run). Heavy imports live inside the commands so ``--help`` is instant."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from cli.errors import EXIT_FAILURE, handle_errors

RunDirArg = Annotated[
    Path, typer.Argument(help="Run directory written by `sonarmap run`.", show_default=False)
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]


@handle_errors
def evaluate(
    run_dir: RunDirArg,
    truth: Annotated[
        Path, typer.Option("--truth", "-t", help="Ground-truth nav2 map (YAML).", dir_okay=False)
    ],
    trajectory: Annotated[
        Path | None,
        typer.Option("--trajectory", help="True trajectory CSV (t,x,y,yaw): recall only counts "
                     "walls within sensor reach of it.", dir_okay=False),
    ] = None,
    tolerance: Annotated[
        float, typer.Option("--tolerance", help="Match distance for occupied cells, m.")
    ] = 0.10,
    reach: Annotated[
        float | None,
        typer.Option("--reach", help="Sensor reach, m (default: the run's largest max range)."),
    ] = None,
    truth_trajectory: Annotated[
        Path | None,
        typer.Option("--truth-trajectory", help="True trajectory CSV (t,x,y,yaw): adds the "
                     "ATE (after SE(2) alignment) and RPE of the run's trajectory.csv.",
                     dir_okay=False),
    ] = None,
    rpe_delta: Annotated[
        float, typer.Option("--rpe-delta", help="RPE pose-pair spacing, in --rpe-unit.")
    ] = 1.0,
    rpe_unit: Annotated[
        str, typer.Option("--rpe-unit", help="RPE spacing unit: m (path length) or frames.")
    ] = "m",
    oblique_deg: Annotated[
        float | None,
        typer.Option("--oblique-deg", help="With --trajectory: count the true walls most of "
                     "the path's sight lines meet more than this far off their normal, degrees (smooth "
                     "walls return no sonar echo beyond 10-30°, docs/SONAR_PHYSICS.md), and "
                     "how many of them the map missed. 0 turns the count off."),
    ] = 30.0,
    json_out: JsonOpt = False,
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="Also write the JSON to this file (atomically).",
                     dir_okay=False),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing --output.")] = False,
    no_report: Annotated[
        bool, typer.Option("--no-report", help="Leave the run's report.html/report.md as they are.")
    ] = False,
) -> None:
    """Score a run's map against a ground-truth map: occupied-cell precision, recall and F1
    within a tolerance, free-space accuracy, unknown fraction, feature distance to the true
    walls and the paper's mean feature variance; with --truth-trajectory also the
    trajectory errors (ATE, RPE, as evo defines them). The results are added to the run's
    report.html and report.md (unless --no-report); nothing else in the run directory is
    ever written to.

    Examples:

      sonarmap evaluate out/office --truth sample_logs/office/office.truth.yaml

      sonarmap evaluate out/office --truth office.truth.yaml --trajectory office.truth.csv

      sonarmap evaluate out/office --truth office.truth.yaml --json -o golden/evaluation.json

      sonarmap evaluate out/drifted --truth office.truth.yaml --truth-trajectory office.truth.csv
    """
    from formats.errors import OutputError
    from formats.writers.atomic import atomic_write_text
    from pipeline.tools.evaluate import evaluate_run

    if output is not None:
        # A run's data files are immutable: results go next to them, never into the run.
        if output.resolve().is_relative_to(run_dir.resolve()):
            raise OutputError("will not write into the run directory (it is immutable)", output)
        if (output.exists() or output.is_symlink()) and not force:
            raise OutputError("exists already; use --force to replace", output)
    result = evaluate_run(run_dir, truth, trajectory=trajectory, tolerance_m=tolerance,
                          sensor_reach_m=reach, truth_trajectory=truth_trajectory,
                          rpe_delta=rpe_delta, rpe_unit=rpe_unit,
                          oblique_deg=oblique_deg or None)
    if output is not None:
        atomic_write_text(output, result.to_json())
    if not no_report and (run_dir / "report.html").is_file():
        from pipeline.stages.run_report import write_run_reports

        write_run_reports(run_dir, evaluation=result.to_dict())
    if json_out:
        typer.echo(json.dumps(result.to_dict(), indent=2))
    else:
        typer.echo(result.format_table())


@handle_errors
def regress(
    run_dir: RunDirArg,
    golden: Annotated[
        Path, typer.Option("--golden", "-g", help="Golden run directory to compare with.",
                           file_okay=False)
    ],
    tolerances: Annotated[
        Path | None,
        typer.Option("--tolerances", help="TOML file of tolerances: keys f1_drop, features_rel, "
                     "mean_feature_variance_rel, map_cells_differ, readings_used_abs.",
                     dir_okay=False),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Compare a run with a golden run: F1 (when the golden has evaluation.json), feature
    count, mean feature variance, map cells and readings used. Exit 0 when within the
    tolerances, 1 with a table of what regressed.

    Default tolerances: F1 drop ≤ 0.01, features ±2 %, mean feature variance ±5 %,
    ≤ 0.5 % of map cells changed class (different grids regress), readings used exact.

    Examples:

      sonarmap regress out/office --golden sample_logs/goldens/office

      sonarmap regress out/office --golden goldens/office --tolerances tolerances.toml --json
    """
    from pipeline.tools.regress import load_tolerances
    from pipeline.tools.regress import regress as run_regress

    result = run_regress(run_dir, golden, load_tolerances(tolerances))
    if json_out:
        typer.echo(json.dumps(result.to_dict(), indent=2))
    elif result.ok:
        typer.echo(f"no regression against {golden}")
        typer.echo(result.format_table())
    else:
        typer.echo(f"REGRESSION against {golden}: {len(result.failed)} of "
                   f"{len(result.rows)} checks failed")
        typer.echo(result.format_table(failed_only=True))
    if not result.ok:
        raise typer.Exit(EXIT_FAILURE)


def register(app: typer.Typer) -> None:
    """Add the ``evaluate`` and ``regress`` commands to ``app``."""
    app.command("evaluate")(evaluate)
    app.command("regress")(regress)
