"""Progress of a run's passes on stderr: "reading" counts the readings pass 1 finds (no
total yet: a log's reading count is only known once it has been read), then "mapping" runs
against that real total, with the rate (readings/s) and time left, then "writing" while
the outputs are written.

On a terminal: rich bars. CI logs and batch jobs have no terminal: there a line
``sonarmap: mapping: N of M readings (P %), R readings/s, E s`` is printed at most every
PLAIN_EVERY_S seconds (and the final state at the end, once any line was printed), so a
long job shows it is alive without flooding the log, and a short one prints nothing."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    Progress,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

PLAIN_EVERY_S = 5.0

Update = Callable[[str, int, int | None], None]  # (stage, done, total or None)


def _count(stage: str, done: int, total: int | None) -> str:
    if stage == "writing":
        return "outputs"
    return f"{done:,}/{total:,} readings" if total is not None else f"{done:,} readings found"


@contextmanager
def reading_progress() -> Iterator[Update]:
    """Yield a ``(stage, done, total)`` callback that reports progress on stderr."""
    console = Console(stderr=True)
    if not console.is_terminal:
        with plain_progress("readings", sys.stderr) as update:
            yield update
        return
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


@contextmanager
def plain_progress(
    unit: str,
    stream: TextIO,
    every_s: float = PLAIN_EVERY_S,
    clock: Callable[[], float] = time.monotonic,
) -> Iterator[Update]:
    """A ``(stage, done, total)`` callback printing one line per ``every_s`` seconds, plus
    the last state when the block ends (when a line was printed before and it moved)."""
    t0 = clock()
    last_line = t0
    printed = False
    pending: list[tuple[str, int, int | None]] = []  # the latest update not printed yet

    def line(stage: str, done: int, total: int | None) -> None:
        elapsed = clock() - t0
        if total is None and done == 0:  # a stage without a count (writing the outputs)
            print(f"sonarmap: {stage}, {elapsed:.0f} s", file=stream, flush=True)
            return
        of = f" of {total:,}" if total is not None else ""
        share = f" ({100.0 * done / total:.0f} %)" if total else ""
        rate = f", {done / elapsed:,.0f} {unit}/s" if elapsed > 0 else ""
        print(f"sonarmap: {stage}: {done:,}{of} {unit}{share}{rate}, {elapsed:.0f} s",
              file=stream, flush=True)

    def update(stage: str, done: int, total: int | None) -> None:
        nonlocal last_line, printed
        now = clock()
        if now - last_line >= every_s:
            line(stage, done, total)
            last_line, printed = now, True
            pending.clear()
        else:
            pending[:] = [(stage, done, total)]

    yield update
    if pending and printed:
        line(*pending[0])
