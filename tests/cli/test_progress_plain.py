"""Progress on a non-terminal stderr (CI logs, batch jobs): plain lines every few seconds."""

from __future__ import annotations

import io

from cli.progress import plain_progress


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_plain_lines_at_most_every_interval_then_the_final_state() -> None:
    out, clock = io.StringIO(), _Clock()
    with plain_progress("readings", out, every_s=5.0, clock=clock) as update:
        update("reading", 0, None)
        clock.t = 6.0
        update("reading", 6_000, None)  # pass 1: no total yet
        for done in range(0, 12_001, 1000):  # one update per second of the clock
            clock.t = 6.0 + done / 1000
            update("mapping", done, 12_000)
    assert out.getvalue().splitlines() == [
        "sonarmap: reading: 6,000 readings, 1,000 readings/s, 6 s",
        "sonarmap: mapping: 5,000 of 12,000 readings (42 %), 455 readings/s, 11 s",
        "sonarmap: mapping: 10,000 of 12,000 readings (83 %), 625 readings/s, 16 s",
        "sonarmap: mapping: 12,000 of 12,000 readings (100 %), 667 readings/s, 18 s",
    ]


def test_a_short_job_prints_nothing() -> None:
    out, clock = io.StringIO(), _Clock()
    with plain_progress("readings", out, every_s=5.0, clock=clock) as update:
        update("mapping", 10, 100)
        clock.t = 1.0
        update("mapping", 100, 100)
    assert out.getvalue() == ""
