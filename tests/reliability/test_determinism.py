"""Same log and configuration → every output byte-identical except metrics.json, whose
only difference is its ``timing`` section: across processes (other hash seeds) and when a
batch maps the logs on one worker or on two."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from fuzz.harness import ROOT, Target
from pipeline.config import Config
from pipeline.run import run
from pipeline.tools.batch import run_batch

SAME_BYTES = ("map.pgm", "map.yaml", "features.parquet", "config.toml", "map.png", "map.mcap",
              "trajectory.csv", "report.html", "report.md")


def _deterministic_metrics(run_dir: Path) -> dict[str, Any]:
    m = json.loads((run_dir / "metrics.json").read_text())
    assert "timing" in m  # the only section allowed to differ
    m.pop("timing")
    return m


def _assert_same_run(a: Path, b: Path) -> None:
    # Every output but metrics.json (batch's own marker, dot-named, is not an output).
    outputs = {p.name for p in a.iterdir() if not p.name.startswith(".")}
    assert outputs == {p.name for p in b.iterdir() if not p.name.startswith(".")}
    assert outputs == {*SAME_BYTES, "metrics.json"}
    for name in SAME_BYTES:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert _deterministic_metrics(a) == _deterministic_metrics(b)


def test_rerun_in_another_process_is_byte_identical(targets: dict[str, Target], tmp_path: Path) -> None:
    log = targets["mcap-zstd"].log
    first = tmp_path / "first"
    result = run(log, first, Config())
    assert result.metrics.counts["features"] > 0
    env = dict(os.environ, PYTHONHASHSEED="12345")  # other set/dict orders of strings
    res = subprocess.run(
        [sys.executable, "-m", "cli", "run", str(log), "-o", str(tmp_path / "second"), "-q"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=120, check=False,
    )
    assert res.returncode == 0, res.stderr
    _assert_same_run(first, tmp_path / "second")


def test_batch_on_one_or_two_workers_is_byte_identical(targets: dict[str, Target], tmp_path: Path) -> None:
    logs = [targets["mcap-zstd"].log, targets["csv-set-ranges.csv"].log, targets["ros1-lz4"].log]
    one = run_batch(logs, tmp_path / "one", None, workers=1)
    two = run_batch(logs, tmp_path / "two", None, workers=2)
    assert one.count("ok") == two.count("ok") == len(logs), [o.error for o in one.outcomes]
    for o in one.outcomes:
        _assert_same_run(tmp_path / "one" / o.name, tmp_path / "two" / o.name)
