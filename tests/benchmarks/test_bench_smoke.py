"""The benchmark runner on tiny inputs (keeps ``python -m benchmarks`` from rotting).

Speed is not asserted: the figures only have to exist and be positive, the table to hold
every section, and the simulated benchmark log to be deterministic and cached.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # benchmarks/ is not an installed package
    sys.path.insert(0, str(ROOT))

from benchmarks import bench_end_to_end as e2e  # noqa: E402


def test_runner_smoke_prints_every_section(tmp_path: Path) -> None:
    env = {**os.environ, "SONARMAP_BENCH_CACHE": str(tmp_path / "cache")}
    results = tmp_path / "RESULTS.md"
    # The timeout only guards against a hang: a cold numba cache on a loaded 2-core
    # machine took over 300 s, so it is far above any healthy run (about 100 s).
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks", "--smoke", "--results", str(results)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800, check=True,
    ).stdout
    rows = [line.split("|")[1:-1] for line in out.splitlines() if line.startswith("| ")]
    rows = [[c.strip() for c in r] for r in rows if r[0].strip() != "section"]
    sections = {r[0] for r in rows}
    assert sections == {"readers", "mapper", "e2e", "scaling", "batch", "regress", "storage"}
    by_case = {r[1]: r for r in rows}
    # Readers: 6 s ROS 1 bags (16 × 10 Hz + 50 Hz odometry) and the 5k-message ROS 2 bag.
    assert "ros1 lz4: 1260 msgs, sonarmap" in by_case
    assert "ros2 mcap: 5100 msgs, sonarmap" in by_case
    assert by_case["ros1 lz4: 1260 msgs, sonarmap"][4].endswith("x rosbags")
    # Mapper: the four methods against OctoMap (when octomap-python is installed, an
    # optional benchmark extra), on the same 320 readings.
    has_octomap = importlib.util.find_spec("octomap") is not None
    for label in ("default method (specular echo attribution, detection measured, 5 passes)",
                  "specular echo attribution (§10, 4 passes)",
                  "echo attribution (§9, 2 passes)", "paper's method (correction on)",
                  "without correction", "classic log-odds baseline"):
        row = by_case[f"320 readings, {label}"]
        assert float(row[2].replace(",", "")) > 0
        assert ("x octomap" in row[4]) == has_octomap
    # End to end: the 20 s log of 16 sonars at 10 Hz, every stage share, shares sum to 100 %.
    assert "sonarmap run, 1x log (3200 readings, MCAP zstd)" in by_case
    assert by_case["sonarmap run, 1x log (3200 readings, MCAP zstd)"][4].endswith(" s CPU")
    assert "; CPU " in by_case["0.5x log (1600 readings)"][4]
    shares = [float(r[2]) for r in rows if r[1].startswith("share: ")]
    assert len(shares) == 5 and sum(shares) == pytest.approx(100.0, abs=0.1)
    assert "0.5x log (1600 readings)" in by_case
    assert "2x log peak RSS" in by_case
    assert float(by_case["2x log"][2]) > 0
    # Batch: 2 smoke logs of 200 steps × 8 sonars, on 1 and on 2 workers.
    assert float(by_case["2 logs x 1600 readings, 1 worker"][2]) > 0
    assert by_case["2 workers"][4].endswith("x of 1 worker")
    # Regress: the suite of the slow-odometry sample beside a batch of it, 2 workers.
    assert float(by_case["sonarmap batch, 1 sample logs, 2 workers"][2]) > 0
    assert by_case["regress --suite, same logs (F1 with truths), 2 workers"][4].endswith("x batch")
    text = results.read_text(encoding="utf-8")
    assert text.startswith("# Benchmark results") and "Machine: " in text
    assert "load average" in text.splitlines()[2]
    assert "| mapper | 320 readings, paper's method (correction on) |" in text


def test_cost_growth_table_splits_the_default_method(capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks import bench_cost_growth
    from pipeline.mapper.andersone import AndersoneMapper

    steps = ("prepare", "add_free_space", "integrate_prepared")
    original = [getattr(AndersoneMapper, name) for name in steps]
    bench_cost_growth.main(["--firings", "40", "--repeat", "1"])
    # the timers are removed again
    assert [getattr(AndersoneMapper, name) for name in steps] == original
    rows = [line.split("|")[1:-1] for line in capsys.readouterr().out.splitlines()
            if line.startswith("| ") and "---" not in line][1:]
    assert [r[0].strip() for r in rows] == [
        "resolution 0.1 m", "resolution 0.05 m", "resolution 0.025 m", "beam 15 deg",
        "beam 30 deg", "beam 60 deg", "match_distance 0.3 m", "match_distance 0.05 m"]
    for r in rows:
        total, paper, own, classic, features = (float(c) for c in r[1:])
        assert total > 0 and 0 < paper <= total and own == pytest.approx(total - paper, abs=0.011)
        assert classic > 0 and features > 0


def test_benchmark_log_is_deterministic_and_cached(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SONARMAP_BENCH_CACHE", str(tmp_path))
    spec = e2e.LogSpec(seconds=5.0)
    log = e2e.cached_log(spec, verbose=False)
    assert log == tmp_path / spec.key / "log.mcap"
    assert spec.key == "v1-office-5s-seed1-ring10hz-zstd"
    digest = hashlib.sha256(log.read_bytes()).hexdigest()
    mtime = log.stat().st_mtime_ns
    assert e2e.cached_log(spec, verbose=False) == log  # reused, not regenerated
    assert log.stat().st_mtime_ns == mtime
    again = tmp_path / "again.mcap"
    assert e2e.simulate_log(spec, again) == 800  # 5 s × 16 sonars × 10 Hz
    assert hashlib.sha256(again.read_bytes()).hexdigest() == digest
