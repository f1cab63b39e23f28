"""A rich progress bar over a run's two passes: "reading" counts the readings pass 1
finds (no total yet: a log's reading count is only known once it has been read), then
"mapping" runs against that real total, with the rate (readings/s) and time left, then
"writing" while the outputs are written."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (
    BarColumn,
    Progress,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


def _count(stage: str, done: int, total: int | None) -> str:
    if stage == "writing":
        return "outputs"
    return f"{done:,}/{total:,} readings" if total is not None else f"{done:,} readings found"


@contextmanager
def reading_progress() -> Iterator[Callable[[str, int, int | None], None]]:
    """Yield a ``(stage, done, total)`` callback that drives a progress bar on stderr.

    On a non-terminal stderr (CI logs, batch jobs) rich draws nothing live.
    """
    console = Console(stderr=True)
    with Progress(
        TextColumn("{task.description:<8}"),
        BarColumn(),
        TextColumn("{task.fields[count]}"),
        TaskProgressColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    ) as bar:
        tasks = {"reading": bar.add_task("reading", total=None, count="", rate="")}
        started = {"reading": time.monotonic()}
        last = [time.monotonic()]

        def update(stage: str, done: int, total: int | None) -> None:
            now = time.monotonic()
            if stage not in tasks:  # the next stage: a fresh bar (its own total or none)
                for old in tasks.values():
                    bar.update(old, visible=False)
                tasks[stage] = bar.add_task(stage, total=total, count="", rate="")
                started[stage] = last[0]  # the previous stage's last word: this one began
            elapsed = now - started[stage]
            rate = f"{done / elapsed:,.0f}/s" if elapsed > 0.5 and done else ""
            bar.update(tasks[stage], completed=done, count=_count(stage, done, total), rate=rate)
            last[0] = now

        yield update
