"""The reader benchmark runs end to end on a tiny bag (speed is not asserted here)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_readers.py"


def test_bench_readers_smoke(capsys: pytest.CaptureFixture[str]) -> None:
    spec = importlib.util.spec_from_file_location("bench_readers", BENCH)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = bench  # dataclasses look their module up
    spec.loader.exec_module(bench)
    figures = bench.main(["--smoke"])
    # 6 s of log: 16 sonars × 10 Hz + Odometry at 50 Hz.
    for bag in ("ros1 uncompressed", "ros1 lz4"):
        assert figures[f"messages {bag} / sonarmap RosLogReader"] == 960 + 300
        assert figures[f"messages {bag} / rosbags AnyReader+deserialize"] == 960 + 300
        assert figures[f"speedup {bag}"] > 0
    assert figures["rss 1x MB"] > 10 and figures["rss 10x MB"] > 10
    out = capsys.readouterr().out
    assert "speed-up over rosbags, ros1 lz4:" in out
    assert "peak RSS of our reader (lz4)" in out
