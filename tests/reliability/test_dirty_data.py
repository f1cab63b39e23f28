"""REP 117 and dirty data: NaN, +inf, −inf, negative and out-of-limit ranges and header
stamps that jump backwards are counted by reason in metrics.json and excluded, and the
map is still produced."""

from __future__ import annotations

import json
import shutil
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

import formats.csv_log
from fuzz.harness import Target
from pipeline.config import Config
from pipeline.run import run
from pipeline.stages.reading_quality import REASONS, classify_readings

# Row index (of the data rows) → the range text written there; spread over the log.
INJECT = {
    40: "nan", 41: "NaN", 90: "inf", 91: "+inf", 140: "-inf", 190: "-0.5", 191: "-3",
    240: "0.02",  # below min_range (0.1 m)
    290: "7.5",  # beyond max_range (5 m)
}
JUMP = range(300, 312)  # these rows' header stamps jump 5 s back


def _dirty_log(src: Path, dst: Path) -> tuple[list[list[str]], set[int]]:
    shutil.copytree(src, dst)
    lines = (dst / "ranges.csv").read_text().splitlines()
    header, rows = lines[0], [ln.split(",") for ln in lines[1:]]
    assert header.split(",")[:3] == ["t", "sensor", "range"]
    for i, text in INJECT.items():
        rows[i][2] = text
    for i in JUMP:
        rows[i][0] = str(Decimal(rows[i][0]) - 5)
    (dst / "ranges.csv").write_text("\n".join([header, *(",".join(r) for r in rows)]) + "\n")
    return rows, set(JUMP)


@pytest.mark.parametrize("chunk_bytes", [2048, formats.csv_log.CHUNK_BYTES])
def test_dirty_readings_are_counted_by_reason_and_excluded(
    targets: dict[str, Target], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, chunk_bytes: int
) -> None:
    # Small chunks: the backward jump crosses reader batches; large: it is inside one.
    monkeypatch.setattr(formats.csv_log, "CHUNK_BYTES", chunk_bytes)
    rows, jumped = _dirty_log(targets["csv-set-ranges.csv"].log, tmp_path / "dirty")
    config = Config()
    result = run(tmp_path / "dirty", tmp_path / "out", config)
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())

    kept = [r for i, r in enumerate(rows) if i not in jumped]
    # Beam limits per sensor, from the log's sensors.csv (sensor,x,y,yaw,fov,min,max).
    limits = {ln.split(",")[0]: ln.split(",")[5:7]
              for ln in (tmp_path / "dirty" / "sensors.csv").read_text().splitlines()[1:]}
    rng = np.array([float(r[2]) for r in kept])
    lo = np.array([float(limits[r[1]][0]) for r in kept])
    hi = np.array([float(limits[r[1]][1]) for r in kept])
    codes = classify_readings(rng, lo, hi, config.mapper.eps_max)
    expected = {REASONS[c]: int((codes == c).sum()) for c in REASONS if c}
    assert expected["nan"] == 2 and expected["neg_inf"] == 1 and expected["negative"] == 2
    assert expected["below_min"] >= 1 and expected["max_range"] >= 1 and expected["pos_inf"] >= 2

    dropped = metrics["dropped"]
    for reason, n in expected.items():
        assert dropped[reason] == n, reason
    assert dropped["stamp_backwards"] == len(jumped) and dropped["late"] == 0
    assert dropped["before_first_pose"] == dropped["after_last_pose"] == dropped["in_pose_gap"] == 0
    counts = metrics["counts"]
    assert counts["readings"] == len(rows)
    assert counts["readings_stamp_backwards"] == len(jumped)
    assert counts["readings_used"] == len(kept) - sum(expected.values())
    # The map is still produced, with obstacles.
    assert result.metrics.counts["features"] > 0
    assert (tmp_path / "out" / "map.pgm").read_bytes().startswith(b"P5")
    assert metrics["map"]["cells_occupied"] > 0
