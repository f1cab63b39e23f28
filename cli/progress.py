"""Progress over readings on stderr: a rich bar on a terminal, plain lines elsewhere.

CI logs and batch jobs have no terminal: there a line ``sonarmap: mapping: N of M readings
(P %), R readings/s, E s`` is printed at most every PLAIN_EVERY_S seconds (and the final
state at the end, once any line was printed), so a long job shows it is alive without
flooding the log, and a short one prints nothing.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TextIO

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

PLAIN_EVERY_S = 5.0

Update = Callable[[int, int], None]  # (done, total)


@contextmanager
def reading_progress() -> Iterator[Update]:
    """Yield a ``(done, total)`` callback that reports mapping progress on stderr."""
    console = Console(stderr=True)
    if not console.is_terminal:
        with plain_progress("mapping", "readings", sys.stderr) as update:
            yield update
        return
    with Progress(
        TextColumn("mapping"),
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
        task = bar.add_task("mapping", total=None, rate="")

        def update(done: int, total: int) -> None:
            elapsed = bar.tasks[0].elapsed or 0.0
            rate = f"{done / elapsed:,.0f}/s" if elapsed > 0 else ""
            bar.update(task, completed=done, total=total, rate=rate)

        yield update


@contextmanager
def plain_progress(
    what: str,
    unit: str,
    stream: TextIO,
    every_s: float = PLAIN_EVERY_S,
    clock: Callable[[], float] = time.monotonic,
) -> Iterator[Update]:
    """A ``(done, total)`` callback printing one line per ``every_s`` seconds, plus the
    last state when the block ends (when a line was printed before and the state moved)."""
    t0 = clock()
    last_line = t0
    printed = False
    state: list[int] = []  # [done, total] of the latest update not printed yet

    def line(done: int, total: int) -> None:
        elapsed = clock() - t0
        share = f" ({100.0 * done / total:.0f} %)" if total else ""
        rate = f", {done / elapsed:,.0f} {unit}/s" if elapsed > 0 else ""
        print(f"sonarmap: {what}: {done:,} of {total:,} {unit}{share}{rate}, "
              f"{elapsed:.0f} s", file=stream, flush=True)

    def update(done: int, total: int) -> None:
        nonlocal last_line, printed
        now = clock()
        if now - last_line >= every_s:
            line(done, total)
            last_line, printed = now, True
            state.clear()
        else:
            state[:] = [done, total]

    yield update
    if state and printed:
        line(*state)
