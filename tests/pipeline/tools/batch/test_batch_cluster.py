"""``sonarmap batch`` end to end on real Dask clusters (2 worker processes, loopback)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest
import typer
from batch_helpers import write_config, write_corrupt_log, write_wall_log
from typer.testing import CliRunner

from pipeline.config import load_config
from pipeline.tools import batch

STEPS = 100  # poses per log; 3 readings each


def _logs(root: Path) -> tuple[list[Path], Path]:
    logs = [write_wall_log(root / "logs" / f"run{i}.csv", steps=STEPS, seed=i) for i in range(3)]
    return logs, write_config(root / "sonarmap.toml")


def _invoke(app: typer.Typer, *args: str) -> tuple[int, str, str]:
    r = CliRunner().invoke(app, ["batch", *args])
    if r.exception is not None and not isinstance(r.exception, SystemExit):
        raise r.exception
    return r.exit_code, r.stdout, r.stderr


def _rows(out: Path) -> list[dict[str, Any]]:
    return pq.read_table(out / "summary.parquet").to_pylist()


def _stamp(d: Path) -> tuple[int, int]:
    """Identity of a finished output: directory inode, metrics.json mtime (ns)."""
    return d.stat().st_ino, (d / "metrics.json").stat().st_mtime_ns


def _deterministic_metrics(d: Path) -> dict[str, Any]:
    m = json.loads((d / "metrics.json").read_text())
    m.pop("timing")
    return dict(m)


def test_local_cluster_three_ok_one_corrupt(tmp_path: Path, cli_app: typer.Typer) -> None:
    logs, cfg = _logs(tmp_path)
    bad = write_corrupt_log(tmp_path / "logs" / "zz_bad.csv")
    out = tmp_path / "out"
    code, stdout, stderr = _invoke(cli_app, str(tmp_path / "logs"), "-o", str(out),
                                   "--config", str(cfg), "--workers", "2")
    assert code == 1
    err_line = f"{bad}: line 3: column 'x': expected a number, found 'zero'"
    assert f"sonarmap: failed: zz_bad: {err_line}" in stderr.splitlines()
    assert "4 logs: 3 mapped, 0 skipped (unchanged), 1 failed" in stdout

    rows = _rows(out)
    assert [r["path"] for r in rows] == sorted(str(p) for p in [*logs, bad])
    assert [(r["name"], r["status"]) for r in rows] == [
        ("run0", "ok"), ("run1", "ok"), ("run2", "ok"), ("zz_bad", "failed")]
    assert rows[3]["error"] == err_line and rows[3]["readings"] is None
    for r in rows[:3]:
        assert r["error"] is None
        assert r["readings"] == 3 * STEPS
        assert r["duration_s"] == pytest.approx(9.902)  # last stamp 9.9 s + 2 ms
        assert isinstance(r["features"], int) and r["features"] > 0
        assert 0 < r["mean_feature_variance_m2"] < 0.05  # m², walls measured ~1 cm noisy
        assert r["mapped_area_m2"] > 1.0
        assert r["seconds"] > 0
    # Each log's output is the single-log run's, plus the resume marker.
    cfg_hash = load_config(cfg).hash()
    for p in logs:
        d = out / p.stem
        metrics = json.loads((d / "metrics.json").read_text())
        assert metrics["counts"]["readings"] == 3 * STEPS
        assert {"map.yaml", "map.pgm", "features.parquet"} <= {f.name for f in d.iterdir()}
        marker = json.loads((d / batch.MARKER).read_text())
        assert marker["input_sha256"] == hashlib.sha256(p.read_bytes()).hexdigest()
        assert marker["config_hash"] == cfg_hash
    assert not (out / "zz_bad").exists()
    assert sorted(f.name for f in out.iterdir()) == [
        "run0", "run1", "run2", "summary.md", "summary.parquet"]
    md = (out / "summary.md").read_text()
    assert "4 logs: 3 mapped, 0 skipped (unchanged), 1 failed." in md
    assert "| zz_bad | failed |" in md and err_line in md


def test_rerun_skips_unchanged_then_remaps(
    tmp_path: Path, cli_app: typer.Typer, scheduler_address: str
) -> None:
    logs, cfg = _logs(tmp_path)
    out = tmp_path / "out"
    args = [str(tmp_path / "logs"), "-o", str(out), "--config", str(cfg),
            "--scheduler", scheduler_address, "--quiet"]
    code, stdout, _ = _invoke(cli_app, *args)
    assert (code, stdout) == (0, "")
    first = {p.stem: _stamp(out / p.stem) for p in logs}
    first_rows = _rows(out)
    first_metrics = _deterministic_metrics(out / "run0")

    # Unchanged: nothing is mapped again; the summary keeps the values, status skipped.
    code, _, _ = _invoke(cli_app, *args)
    assert code == 0
    rows = _rows(out)
    assert [r["status"] for r in rows] == ["skipped"] * 3
    assert {p.stem: _stamp(out / p.stem) for p in logs} == first
    for a, b in zip(first_rows, rows, strict=True):
        assert (a["readings"], a["features"], a["mapped_area_m2"]) == (
            b["readings"], b["features"], b["mapped_area_m2"])

    marker0 = (out / "run0" / batch.MARKER).read_bytes()

    # One input changed: only that one is mapped again.
    write_wall_log(logs[1], steps=STEPS + 20, seed=7)
    code, _, _ = _invoke(cli_app, *args)
    rows = _rows(out)
    assert [r["status"] for r in rows] == ["skipped", "ok", "skipped"]
    assert rows[1]["readings"] == 3 * (STEPS + 20)
    assert _stamp(out / "run1") != first["run1"]
    assert _stamp(out / "run0") == first["run0"]

    # --rerun maps everything again, replacing the outputs.
    code, _, _ = _invoke(cli_app, *args, "--rerun")
    assert code == 0
    assert [r["status"] for r in _rows(out)] == ["ok"] * 3
    assert _stamp(out / "run0") != first["run0"]
    assert _deterministic_metrics(out / "run0") == first_metrics  # same input, same map
    assert (out / "run0" / batch.MARKER).read_bytes() == marker0
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]  # no staging left


def test_config_change_and_markerless_output_are_remapped(
    tmp_path: Path, cli_app: typer.Typer, scheduler_address: str
) -> None:
    logs, cfg = _logs(tmp_path)
    out = tmp_path / "out"
    # A plain `sonarmap run` output (no batch marker) is re-mapped and replaced ...
    ran = CliRunner().invoke(cli_app, ["run", str(logs[0]), "-o", str(out / "run0"), "-q",
                                       "--config", str(cfg)])
    assert ran.exit_code == 0, ran.output
    # ... a directory of the user's under a log's name is not: that log fails, files kept.
    (out / "run1").mkdir(parents=True)
    (out / "run1" / "notes.txt").write_text("the user's own")
    args = [str(logs[0]), str(logs[1]), "-o", str(out), "--scheduler", scheduler_address, "-q"]
    code, _, err = _invoke(cli_app, *args, "--config", str(cfg))
    assert code == 1
    assert err.strip() == (f"sonarmap: failed: run1: {out / 'run1'}: exists and is not a "
                           "sonarmap output; not replacing it, choose another output directory")
    assert (out / "run1" / "notes.txt").read_text() == "the user's own"
    assert sorted(p.name for p in (out / "run1").iterdir()) == ["notes.txt"]
    assert (out / "run0" / batch.MARKER).is_file()
    (out / "run1" / "notes.txt").unlink()
    (out / "run1").rmdir()
    assert _invoke(cli_app, *args, "--config", str(cfg))[0] == 0
    cfg2 = write_config(tmp_path / "coarse.toml").read_text().replace(
        "resolution = 0.1", "resolution = 0.2")
    (tmp_path / "coarse.toml").write_text(cfg2)
    assert _invoke(cli_app, *args, "--config", str(tmp_path / "coarse.toml"))[0] == 0
    assert [r["status"] for r in _rows(out)] == ["ok", "ok"]
    marker = json.loads((out / "run0" / batch.MARKER).read_text())
    assert marker["config_hash"] == load_config(tmp_path / "coarse.toml").hash()


def test_manifest_input_and_equal_names(
    tmp_path: Path, cli_app: typer.Typer, scheduler_address: str
) -> None:
    a = write_wall_log(tmp_path / "site_a" / "day.csv", steps=60, seed=1)
    b = write_wall_log(tmp_path / "site_b" / "day.csv", steps=60, seed=2)
    c = write_wall_log(tmp_path / "site_b" / "night.csv", steps=60, seed=3)
    cfg = write_config(tmp_path / "sonarmap.toml")
    lists = tmp_path / "lists"
    lists.mkdir()
    (lists / "one.txt").write_text("# site A\n../site_a/day.csv\n\n../site_b/day.csv\n")
    (lists / "two.txt").write_text(f"{c}\n")
    out = tmp_path / "out"
    code, _, stderr = _invoke(cli_app, f"@{lists / 'one.txt'}", "--manifest",
                              str(lists / "two.txt"), "-o", str(out), "-c", str(cfg),
                              "--scheduler", scheduler_address, "-q")
    assert code == 0, stderr
    ha = hashlib.sha256(str(a).encode()).hexdigest()[:8]
    hb = hashlib.sha256(str(b).encode()).hexdigest()[:8]
    rows = _rows(out)
    assert [(r["path"], r["name"], r["status"]) for r in rows] == [
        (str(a), f"day-{ha}", "ok"), (str(b), f"day-{hb}", "ok"), (str(c), "night", "ok")]
    assert all(r["readings"] == 180 for r in rows)
    assert (out / f"day-{ha}" / "map.yaml").is_file() and (out / "night" / "map.yaml").is_file()


def test_directory_search_maps_only_logs(
    tmp_path: Path, cli_app: typer.Typer, scheduler_address: str
) -> None:
    root = tmp_path / "data"
    write_wall_log(root / "x" / "one.csv", steps=50)
    write_wall_log(root / "sim.truth.csv", steps=50)
    (root / "README.md").write_text("# data\nthese are logs\n")
    (root / "path.waypoints.csv").write_text("x,y\n0,0\n1,1\n")
    cfg = write_config(tmp_path / "sonarmap.toml")
    out = root / "out"  # inside the searched tree: its outputs are not inputs next time
    for _ in range(2):
        code, _, stderr = _invoke(cli_app, str(root), "-o", str(out), "-c", str(cfg),
                                  "--scheduler", scheduler_address, "-q")
        assert code == 0, stderr
        assert [(r["name"], r["readings"]) for r in _rows(out)] == [("one", 150)]


def test_unreachable_scheduler_is_one_line_error(
    tmp_path: Path, cli_app: typer.Typer, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(batch, "SCHEDULER_TIMEOUT_S", 1.0)
    log = write_wall_log(tmp_path / "a.csv", steps=20)
    code, _, stderr = _invoke(cli_app, str(log), "-o", str(tmp_path / "out"),
                              "--scheduler", "tcp://127.0.0.1:9", "-q")
    assert code == 1
    assert stderr.startswith(
        "sonarmap: error: cannot connect to the Dask scheduler at tcp://127.0.0.1:9")
    assert len(stderr.strip().splitlines()) == 1


def test_no_inputs_is_a_usage_error(tmp_path: Path, cli_app: typer.Typer) -> None:
    code, _, stderr = _invoke(cli_app, "-o", str(tmp_path / "out"))
    assert code == 2
    assert "give at least one log, directory or @MANIFEST" in stderr


def test_run_batch_api_reports_progress_per_log(tmp_path: Path, scheduler_address: str) -> None:
    logs, cfg = _logs(tmp_path)
    calls: list[tuple[int, int]] = []
    result = batch.run_batch(logs[:2], tmp_path / "out", cfg, workers=None,
                             scheduler=scheduler_address, rerun=False,
                             progress=lambda done, total: calls.append((done, total)))
    assert calls == [(0, 2), (1, 2), (2, 2)]
    assert result.ok and result.count("ok") == 2
    assert [o.name for o in result.outcomes] == ["run0", "run1"]
    assert result.summary_parquet == tmp_path / "out" / "summary.parquet"
