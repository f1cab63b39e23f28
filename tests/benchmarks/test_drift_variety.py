"""benchmarks.drift_variety: the summary line that counts the rows reaching the target."""

from __future__ import annotations

import math

from benchmarks.drift_variety import TARGET, Scored, Tally


def _refined(f1: float, aligned: float) -> Scored:
    return Scored(f1=f1, f1_aligned=aligned, ate=0.05, refinement={})


def test_the_tally_counts_rows_at_the_target_in_the_frame_and_aligned() -> None:
    tally = Tally()
    tally.add(0.8, _refined(0.8 * TARGET, 0.8), 0.8)  # exactly at the target: counted
    tally.add(0.5, _refined(0.2, 0.49), 0.47)  # a turned map: only its aligned F1 reaches it
    assert tally.refined == [TARGET, 0.4]
    assert math.isclose(tally.cost[1], 0.03)
    assert tally.summary() == ("refined/true: 1 / 2 ≥ 0.9× (mean 0.6500); aligned: "
                               "2 / 2 ≥ 0.9× (mean 0.9900); true poses refined cost at most "
                               "0.030 F1")


def test_an_empty_tally_says_so() -> None:
    assert Tally().summary() == "no rows"
