"""A rich progress bar over a run's two passes: "reading" counts the readings pass 1
finds (no total yet: a log's reading count is only known once it has been read), then
"mapping" runs against that real total, with the rate (readings/s) and time left."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


@contextmanager
def reading_progress() -> Iterator[Callable[[str, int, int | None], None]]:
    """Yield a ``(stage, done, total)`` callback that drives a progress bar on stderr.

    On a non-terminal stderr (CI logs, batch jobs) rich draws nothing live.
    """
    console = Console(stderr=True)
    with Progress(
        TextColumn("{task.description:<8}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("readings"),
        TaskProgressColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    ) as bar:
        task = bar.add_task("reading", total=None, rate="")
        stage_of_task = ["reading"]

        def update(stage: str, done: int, total: int | None) -> None:
            if stage != stage_of_task[0]:  # pass 2 starts: a fresh bar with the real total
                stage_of_task[0] = stage
                bar.reset(task, total=total, description=stage, rate="")
            elapsed = bar.tasks[0].elapsed or 0.0
            rate = f"{done / elapsed:,.0f}/s" if elapsed > 0 else ""
            bar.update(task, completed=done, total=total, rate=rate)

        yield update
