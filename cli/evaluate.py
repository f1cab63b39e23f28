"""``sonarmap evaluate`` (a run against ground truth) and ``sonarmap regress`` (a run
against a golden run). Heavy imports live inside the commands so ``--help`` is instant."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from cli.errors import EXIT_FAILURE, handle_errors

RunDirArg = Annotated[
    str, typer.Argument(help="Run directory written by `sonarmap run`, or its object-store "
                        "prefix (read only when complete: its .sonarmap-output marker lists "
                        "exactly what is there).", show_default=False)
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]


@handle_errors
def evaluate(
    run_dir: RunDirArg,
    truth: Annotated[
        Path, typer.Option("--truth", "-t", help="Ground-truth nav2 map (YAML).")
    ],
    trajectory: Annotated[
        Path | None,
        typer.Option("--trajectory", help="True trajectory CSV (t,x,y,yaw): recall only counts "
                     "walls within sensor reach of it."),
    ] = None,
    tolerance: Annotated[
        float, typer.Option("--tolerance", help="Farthest a map wall cell may lie from the true wall cell it pairs with, m.")
    ] = 0.10,
    reach: Annotated[
        float | None,
        typer.Option("--reach", help="Sensor reach, m (default: the run's largest max range)."),
    ] = None,
    truth_trajectory: Annotated[
        Path | None,
        typer.Option("--truth-trajectory", help="True trajectory CSV (t,x,y,yaw): adds the "
                     "ATE (after SE(2) alignment) and RPE of the run's trajectory.csv."),
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
        typer.Option("--output", "-o", help="Also write the JSON to this file (atomically)."),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing --output.")] = False,
    no_report: Annotated[
        bool, typer.Option("--no-report", help="Leave the run's report.html/report.md as they are.")
    ] = False,
) -> None:
    """Score a run's map against a ground-truth map: wall precision, recall and F1 (walls
    thinned to one-cell lines, paired one to one within a tolerance), free-space accuracy, unknown fraction, feature distance to the true
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
    import contextlib

    from cli.errors import location_argument
    from formats.storage.location import Url
    from formats.writers.remote_output import complete_output

    where = location_argument(run_dir)
    with contextlib.ExitStack() as stack:
        local = stack.enter_context(complete_output(where))
        _evaluate(local, truth, trajectory, tolerance, reach, truth_trajectory, rpe_delta,
                  rpe_unit, output, force, oblique_deg or None,
                  # a prefix's report is not rewritten: the prefix stays as it was written
                  no_report or isinstance(where, Url), json_out)


def _evaluate(run_dir: Path, truth: Path, trajectory: Path | None, tolerance: float,
              reach: float | None, truth_trajectory: Path | None, rpe_delta: float,
              rpe_unit: str, output: Path | None, force: bool, oblique_deg: float | None,
              no_report: bool, json_out: bool) -> None:
    from formats.writers.atomic import atomic_write_text, check_output_file
    from formats.writers.nav2_map import nav2_image_path
    from formats.writers.output_marker import written_files_in
    from pipeline.tools.evaluate import evaluate_run

    inputs = [(run_dir, "the run directory"), (truth, "the truth map")]
    inputs += [(p, f"the {what}") for p, what in ((trajectory, "trajectory"),
               (truth_trajectory, "truth trajectory")) if p is not None]

    def check_output() -> None:
        # Before the work, and again before writing: the truth image is known once its
        # YAML has been read.
        if output is not None:
            image = nav2_image_path(truth)
            found = inputs + ([(image, "the truth map's image")] if image is not None else [])
            check_output_file(output, kind="evaluation", force=force, inputs=tuple(found))

    check_output()
    result = evaluate_run(run_dir, truth, trajectory=trajectory, tolerance_m=tolerance,
                          sensor_reach_m=reach, truth_trajectory=truth_trajectory,
                          rpe_delta=rpe_delta, rpe_unit=rpe_unit,
                          oblique_deg=oblique_deg)
    if output is not None:
        check_output()
        atomic_write_text(output, result.to_json())
    # The reports are rewritten only in a run directory sonarmap proves it wrote.
    if not no_report and "report.html" in (written_files_in(run_dir) or ()):
        from pipeline.stages.run_report import write_run_reports

        write_run_reports(run_dir, evaluation=result.to_dict())
    if json_out:
        typer.echo(json.dumps(result.to_dict(), indent=2))
    else:
        typer.echo(result.format_table())


@handle_errors
def regress(
    run_dir: Annotated[
        str | None,
        typer.Argument(help="Run directory written by `sonarmap run`, or its complete "
                       "object-store prefix (not with --suite).", show_default=False),
    ] = None,
    golden: Annotated[
        str | None,
        typer.Option("--golden", "-g", help="Golden run directory (or complete object-store "
                     "prefix) to compare RUN with."),
    ] = None,
    tolerances: Annotated[
        Path | None,
        typer.Option("--tolerances", help="TOML file of tolerances: keys f1_drop, features_rel, "
                     "mean_feature_variance_rel, map_cells_differ, readings_used_abs "
                     "(with --suite: instead of the suite file's)."),
    ] = None,
    json_out: JsonOpt = False,
    suite: Annotated[
        Path | None,
        typer.Option("--suite", help="Suite file (TOML) listing the logs to map and hold to "
                     "their goldens (see docs/ci.md).", dir_okay=False, metavar="FILE"),
    ] = None,
    goldens: Annotated[
        Path | None,
        typer.Option("--goldens", help="With --suite: the directory holding one golden "
                     "per log, DIR/<name>.", file_okay=False, metavar="DIR"),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option("--workers", "-w", min=1, metavar="N", help="With --suite: local worker "
                     "processes (default: the CPUs this process may use)."),
    ] = None,
    junit: Annotated[
        Path | None,
        typer.Option("--junit", help="With --suite: write a JUnit XML report here (a test "
                     "case per log).", dir_okay=False, metavar="FILE"),
    ] = None,
    diff_dir: Annotated[
        Path | None,
        typer.Option("--diff-dir", help="With --suite: a PNG per log whose map changed, "
                     "DIR/<name>.png.", file_okay=False, metavar="DIR"),
    ] = None,
    summary: Annotated[
        Path | None,
        typer.Option("--summary", help="With --suite: append a Markdown summary to this file "
                     "(e.g. $GITHUB_STEP_SUMMARY).", dir_okay=False, metavar="FILE"),
    ] = None,
    diff_link: Annotated[
        str | None,
        typer.Option("--diff-link", help="With --summary: link each diff as URL/<name>.png "
                     "(default: the picture's path relative to the summary).", metavar="URL"),
    ] = None,
    update: Annotated[
        bool, typer.Option("--update", help="With --suite: write or replace each log's golden "
                           "(atomically; only goldens sonarmap wrote) and print what moved.")
    ] = False,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="With --suite: no progress bar.")
    ] = False,
) -> None:
    """Compare a run with a golden run: F1 (when the golden has evaluation.json), feature
    count, mean feature variance, map cells and readings used. Exit 0 when within the
    tolerances, 1 with a table of what regressed.

    With --suite FILE --goldens DIR: map every log the suite lists (in parallel, as
    `sonarmap batch`) and compare each with DIR/<name>; one table, exit 0 only when every
    log holds. --update writes the goldens instead.

    Default tolerances: F1 drop ≤ 0.01, features ±2 %, mean feature variance ±5 %,
    ≤ 0.5 % of map cells changed class (different grids regress), readings used exact.

    Examples:

      sonarmap regress out/office --golden sample_logs/goldens/office

      sonarmap regress out/office --golden goldens/office --tolerances tolerances.toml --json

      sonarmap regress --suite regress.toml --goldens goldens --junit report.xml --diff-dir diffs

      sonarmap regress --suite regress.toml --goldens goldens --update
    """
    if suite is not None:
        from cli.regress_suite import regress_suite

        if run_dir is not None or golden is not None:
            raise typer.BadParameter("--suite runs its own logs: give no RUN or --golden",
                                     param_hint="--suite")
        if goldens is None:
            raise typer.BadParameter("--suite needs --goldens DIR", param_hint="--goldens")
        if json_out:
            raise typer.BadParameter("--json is for one run; use --junit with --suite",
                                     param_hint="--json")
        if update and diff_dir is not None:
            raise typer.BadParameter("--update writes goldens, it draws no diffs",
                                     param_hint="--diff-dir")
        regress_suite(suite, goldens, tolerances=tolerances, workers=workers, junit=junit,
                      diff_dir=diff_dir, summary=summary, diff_link=diff_link, update=update,
                      quiet=quiet)
        return
    suite_only = {"--goldens": goldens, "--workers": workers, "--junit": junit,
                  "--diff-dir": diff_dir, "--summary": summary, "--diff-link": diff_link}
    for flag, value in [*suite_only.items(), ("--update", update or None)]:
        if value is not None:
            raise typer.BadParameter(f"{flag} needs --suite", param_hint=flag)
    if run_dir is None or golden is None:
        raise typer.BadParameter("give RUN --golden DIR, or --suite FILE --goldens DIR",
                                 param_hint="RUN")

    import contextlib

    from cli.errors import location_argument
    from formats.writers.remote_output import complete_output
    from pipeline.tools.regress import load_tolerances
    from pipeline.tools.regress import regress as run_regress

    with contextlib.ExitStack() as stack:
        local_run = stack.enter_context(complete_output(location_argument(run_dir)))
        local_golden = stack.enter_context(complete_output(location_argument(golden), "golden"))
        result = run_regress(local_run, local_golden, load_tolerances(tolerances))
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
