"""benchmarks.refine_time: the smallest of alternating rounds, the refined run's stages, and
the table's verdict against the 3× target."""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks.refine_time import Timed, markdown, time_case


def test_a_case_is_the_smallest_of_its_alternating_rounds(tmp_path: Path) -> None:
    calls: list[tuple[str, bool]] = []
    walls = iter([1.5, 3.2, 1.2, 2.9, 1.4, 3.0])  # unrefined, refined, unrefined, …
    cpus = iter([1.1, 4.0, 1.3, 3.5, 1.2, 3.9])  # the smallest CPU need not be the fastest

    def runner(log: Path, out: Path, refine: bool) -> tuple[float, float]:
        calls.append((out.name, refine))
        out.mkdir(exist_ok=True)
        stages = {"pose_refinement": 1.1, "mapping": 0.3, "total": 2.0}
        (out / "metrics.json").write_text(json.dumps({"timing": {"stage_seconds": stages}}))
        return next(walls), next(cpus)

    timed = time_case("loop", tmp_path / "loop.mcap", tmp_path, rounds=3, runner=runner)
    assert calls == [("loop-unrefined", False), ("loop-refined", True)] * 3
    assert timed == Timed("loop", 1.2, 2.9, 1.1, 0.3, 1.1, 3.5)
    assert abs(timed.ratio - 2.9 / 1.2) < 1e-12


def test_the_table_names_the_largest_ratio_and_counts_the_cases_within_the_target() -> None:
    rows = [Timed("office", 1.3, 2.0, 0.6, 0.2, 1.0, 2.5), Timed("loop", 1.0, 3.1, 1.1, 0.1,
                                                                   0.8, 2.0)]
    table = markdown(rows)
    assert "| office | 1.30 | 2.00 | 1.54× | 0.60 | 0.20 | 1.00 | 2.50 | 2.50× |" in table
    assert table.endswith("1 / 2 at most 3× (largest: loop, 3.10×)")
