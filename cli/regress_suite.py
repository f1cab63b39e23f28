"""``sonarmap regress --suite``: the command's side (engine: :mod:`pipeline.tools.suite`)."""

from __future__ import annotations

import contextlib
from pathlib import Path

import typer

from cli.errors import EXIT_FAILURE
from formats.errors import OutputError
from formats.writers.atomic import make_dir


def _make_parent(path: Path) -> None:
    make_dir(path.parent, f"directory of {path.name}")


def regress_suite(
    suite_path: Path,
    goldens: Path,
    *,
    tolerances: Path | None,
    workers: int | None,
    junit: Path | None,
    diff_dir: Path | None,
    summary: Path | None,
    diff_link: str | None,
    update: bool,
    quiet: bool,
) -> None:
    """Run the suite, print its table, write the reports; exit 1 unless every log holds."""
    from cli.batch import _log_progress
    from formats.writers.junit_xml import write_junit_xml
    from pipeline.tools.suite.report import junit_cases, suite_markdown, suite_table
    from pipeline.tools.suite.run_suite import run_suite
    from pipeline.tools.suite.suite_file import read_suite

    suite = read_suite(suite_path)
    for report in (junit, summary):  # made before the suite runs, not found missing after
        if report is not None:
            _make_parent(report)
    with contextlib.ExitStack() as stack:
        progress = None if quiet else stack.enter_context(_log_progress("regress"))
        result = run_suite(suite, goldens, workers=workers, update=update, diff_dir=diff_dir,
                           tolerances=tolerances, progress=progress)
    typer.echo(suite_table(result))
    if junit is not None:
        write_junit_xml(junit, f"sonarmap regress {suite.path.name}", junit_cases(result))
    if summary is not None:
        text = suite_markdown(result, summary, diff_link)
        try:  # appended: $GITHUB_STEP_SUMMARY collects every step's summary
            with summary.open("a", encoding="utf-8") as f:
                f.write(text)
        except OSError as err:
            raise OutputError(f"cannot write the summary: {err.strerror or err}",
                              summary) from err
    if not result.ok:
        raise typer.Exit(EXIT_FAILURE)
