"""Smoke test of benchmarks/bench_memory.py: both logs are made and mapped in fresh
processes and their peak RSS read (the figures themselves are the benchmark's job)."""

from __future__ import annotations

from pathlib import Path

from benchmarks.bench_memory import measure


def test_bench_memory_smoke(tmp_path: Path) -> None:
    rows = measure(0.5, 2, tmp_path)  # one corridor length, then two
    assert list(rows) == ["1x", "2x"]
    one, two = rows["1x"], rows["2x"]
    assert two["duration_s"] > 1.5 * one["duration_s"]  # the same route driven twice as long
    assert two["readings"] > 1.5 * one["readings"]
    for r in (one, two):
        assert 20 * 1024 < r["peak_rss_kib"] < 4 * 1024 * 1024  # KiB: a real process figure
        assert r["features"] > 0
