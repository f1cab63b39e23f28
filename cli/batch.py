"""``sonarmap batch``: map many logs in parallel on Dask (engine: :mod:`pipeline.tools.batch`)."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from cli.errors import EXIT_FAILURE, handle_errors

if TYPE_CHECKING:
    from formats.storage.location import Location


@contextmanager
def _log_progress(command: str = "batch") -> Iterator[Callable[[int, int], None]]:
    """A ``(done, total)`` callback driving a rich progress bar over logs on stderr; on a
    non-terminal (CI, cron) a plain line per finished log instead, named by ``command``."""
    from rich.console import Console

    from cli.progress import plain_progress

    if not Console(stderr=True).is_terminal:
        with plain_progress("logs", sys.stderr, every_s=0.0) as plain:
            yield lambda done, total: plain(command, done, total)
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("mapping"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("logs"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        task = bar.add_task("logs", total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


def split_inputs(
    inputs: list[str], manifests: list[Path]
) -> tuple[list[Location], list[Path]]:
    """``@FILE`` arguments are manifests; the rest are log files, directories or URLs."""
    from cli.errors import check_path_arguments, location_argument

    paths: list[Location] = []
    lists = list(manifests)
    for s in inputs:
        if s.startswith("@") and len(s) > 1:
            lists.append(Path(s[1:]))
        else:
            paths.append(location_argument(s))
    check_path_arguments([paths, lists])  # local paths only: URLs are not checked
    return paths, lists


def register(app: typer.Typer) -> None:
    """Add the ``batch`` command to ``app``."""

    @app.command()
    @handle_errors
    def batch(
        output: Annotated[
            str, typer.Option("--output", "-o", help="Output directory (created if missing), "
                              "or an object-store prefix (s3://bucket/prefix) the workers "
                              "write to directly.")
        ],
        inputs: Annotated[
            list[str] | None,
            typer.Argument(
                help="Log files, directories (searched recursively) or @MANIFEST files.",
                metavar="INPUTS...",
                show_default=False,
            ),
        ] = None,
        config: Annotated[
            Path | None,
            typer.Option("--config", "-c", help="TOML configuration for every log."),
        ] = None,
        manifest: Annotated[
            list[Path] | None,
            typer.Option("--manifest", help="File listing one log path per line, the files "
                         "of one recording joined by ' + ' (repeatable; same as @FILE).",
                         metavar="FILE"),
        ] = None,
        workers: Annotated[
            int | None,
            typer.Option("--workers", "-w", min=1,
                         help="Local worker processes (default: the CPUs this process may use)."),
        ] = None,
        scheduler: Annotated[
            str | None,
            typer.Option("--scheduler", help="Use an existing Dask cluster, e.g. "
                         "tcp://10.0.0.5:8786 (then --workers is ignored)."),
        ] = None,
        memory_limit: Annotated[
            str,
            typer.Option("--memory-limit", help="Memory per local worker, e.g. 4GB "
                         "(default auto: the machine's memory / --workers; at least 512MB, 0 = no "
                         "limit); a log that "
                         "needs more fails as its own row."),
        ] = "auto",
        rerun: Annotated[
            bool, typer.Option("--rerun", help="Map every log again, even unchanged ones.")
        ] = False,
        quiet: Annotated[
            bool, typer.Option("--quiet", "-q", help="No progress bar or summary line.")
        ] = False,
    ) -> None:
        """Map many logs in parallel: each as `sonarmap run` would, into OUTPUT/<name>/,
        plus OUTPUT/summary.parquet and OUTPUT/summary.md (one row per log).

        INPUTS are log files, directories and manifests. A directory that is a rosbag2 bag
        (has metadata.yaml) or a CSV log set is one log; any other directory is searched
        recursively for files whose content is a log (hidden entries, *.truth.* files and
        sonarmap's own outputs are skipped). A manifest (@FILE or --manifest FILE) lists
        one path per line, relative to the manifest; lines starting with # are comments;
        a line 'sonar.bag + odom.bag' is one recording in several files, mapped as one log
        (into OUTPUT/odom+sonar/). Equal names become <name>-<8 hex digits of the path's
        sha256>.

        Runs on Dask: a local cluster of --workers single-threaded processes on loopback,
        or an existing cluster with --scheduler. A finished log leaves
        OUTPUT/<name>/.sonarmap-done.json; running again skips logs whose input and
        configuration are unchanged (--rerun maps them again). A log that fails does not
        stop the others; failures are listed on stderr, one line each, and the exit code
        is 1 when any log failed.

        Examples:

          sonarmap batch logs/ -o out/

          sonarmap batch a.bag b.mcap rosbag2_dir -o out/ --config sonarmap.toml --workers 4

          sonarmap batch @logs.txt -o out/ --scheduler tcp://10.0.0.5:8786

          sonarmap batch logs/ -o out/ --rerun
        """
        from cli.errors import location_argument
        from pipeline.tools.batch import run_batch

        out = location_argument(output)  # a local OUT: its names checked before any work
        paths, lists = split_inputs(inputs or [], manifest or [])
        if not paths and not lists:
            raise typer.BadParameter("give at least one log, directory or @MANIFEST",
                                     param_hint="INPUTS")
        with contextlib.ExitStack() as stack:
            progress = None if quiet else stack.enter_context(_log_progress())
            result = run_batch(paths, out, config, workers=workers, scheduler=scheduler,
                               rerun=rerun, progress=progress, manifests=lists,
                               memory_limit=memory_limit)
        for row in result.failures:
            print(f"sonarmap: failed: {row.name}: {row.error}", file=sys.stderr)
        for row in result.unread:
            print(f"sonarmap: skipped: {row.path}: {row.error}", file=sys.stderr)
        if not quiet:
            unread = f", {len(result.unread)} directories not read" if result.unread else ""
            typer.echo(
                f"{len(result.outcomes)} logs: {result.count('ok')} mapped, "
                f"{result.count('skipped') - len(result.unread)} skipped (unchanged), "
                f"{result.count('failed')} failed{unread}; summary in {result.summary_md}"
            )
        if not result.ok:
            raise typer.Exit(EXIT_FAILURE)
