"""`sonarmap run` end to end through the CLI, on every sample log."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from cli.app import app
from formats.writers.nav2_map import load_nav2_map

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_logs"

OUTPUTS = {"map.pgm", "map.yaml", "map.png", "features.parquet", "metrics.json", "config.toml",
           "report.html", "report.md", ".sonarmap-output"}

SAMPLE_RUNS = [
    ("office.mcap", [str(SAMPLES / "office" / "office.mcap")], "mcap"),
    ("office.bag", [str(SAMPLES / "office" / "office.bag")], "ros1"),
    ("office_ros2", [str(SAMPLES / "office" / "office_ros2")], "ros2-sqlite3"),
    ("office_csv", [str(SAMPLES / "office" / "office_csv")], "csv"),
    ("udacity", [str(SAMPLES / "udacity-8sonar"), "--config",
                 str(SAMPLES / "udacity-8sonar" / "sonarmap.toml")], "csv"),
]


def _run(runner, args):
    result = runner.invoke(app, args)
    return result


@pytest.mark.parametrize(("name", "args", "fmt"), SAMPLE_RUNS, ids=[r[0] for r in SAMPLE_RUNS])
def test_every_sample_log_produces_all_outputs(runner, tmp_path, name, args, fmt):
    out = tmp_path / name
    result = _run(runner, ["run", *args, "-o", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} == OUTPUTS
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["input"]["format"] == fmt
    assert metrics["counts"]["readings"] > 1000
    assert metrics["counts"]["features"] > 0
    assert metrics["map"]["cells_occupied"] > 0 and metrics["map"]["cells_free"] > 0
    assert metrics["paper_metric"]["mean_feature_variance_m2"] > 0
    assert set(metrics["timing"]["stage_seconds"]) >= {"ingest", "pose_sync", "scan_building", "mapping"}
    # The effective configuration is written and loads back.
    tomllib.loads((out / "config.toml").read_text())


def test_the_same_run_in_every_format_gives_the_same_map(runner, tmp_path):
    digests = set()
    for name, args, _ in SAMPLE_RUNS[:4]:
        out = tmp_path / name
        assert _run(runner, ["run", *args, "-o", str(out), "-q"]).exit_code == 0
        digests.add((out / "map.pgm").read_bytes())
    assert len(digests) == 1


def test_nav2_map_reloads_to_the_same_occupancy_classes(runner, tmp_path):
    out = tmp_path / "o"
    assert _run(runner, ["run", str(SAMPLES / "office" / "office.mcap"), "-o", str(out), "-q"]).exit_code == 0
    yaml_text = (out / "map.yaml").read_text()
    for line in ("image: map.pgm", "mode: trinary", "negate: 0", "occupied_thresh: 0.65", "free_thresh: 0.196"):
        assert line in yaml_text
    m = load_nav2_map(out / "map.yaml")
    metrics = json.loads((out / "metrics.json").read_text())["map"]
    assert m.classes.shape == (metrics["height"], metrics["width"])
    assert int((m.classes == 1).sum()) == metrics["cells_occupied"]
    assert int((m.classes == 0).sum()) == metrics["cells_free"]
    assert int((m.classes == -1).sum()) == metrics["cells_unknown"]
    assert (m.grid.origin_x, m.grid.origin_y) == tuple(metrics["origin"][:2])
    pgm = (out / "map.pgm").read_bytes()
    assert pgm.startswith(b"P5\n")
    assert set(np.frombuffer(pgm[-m.classes.size:], np.uint8).tolist()) <= {0, 205, 254}


def test_features_parquet_schema(runner, tmp_path):
    out = tmp_path / "o"
    assert _run(runner, ["run", str(SAMPLES / "office" / "office.mcap"), "-o", str(out), "-q"]).exit_code == 0
    table = pq.read_table(out / "features.parquet")
    assert table.column_names == ["id", "x", "y", "cov_xx", "cov_xy", "cov_yy", "sigma_major",
                                  "sigma_minor", "orientation", "measured_times", "first_seen_ns",
                                  "last_seen_ns", "merges"]
    meta = {k.decode(): v.decode() for k, v in table.schema.metadata.items()}
    assert meta["frame"] == "map"
    assert json.loads(meta["units"])["x"] == "m"
    cfg_hash = json.loads((out / "metrics.json").read_text())["run"]["config_hash"]
    assert meta["config_hash"] == cfg_hash
    assert float(meta["resolution_m"]) == 0.05
    assert table.num_rows == json.loads((out / "metrics.json").read_text())["counts"]["features"]


def test_reruns_are_byte_identical(runner, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    log = str(SAMPLES / "office" / "office.bag")
    for out in (a, b):
        assert _run(runner, ["run", log, "-o", str(out), "-q"]).exit_code == 0
    for name in ("map.pgm", "map.yaml", "features.parquet", "config.toml", "map.png"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    ma, mb = (json.loads((d / "metrics.json").read_text()) for d in (a, b))
    ma.pop("timing"), mb.pop("timing")
    assert ma == mb


def test_existing_output_is_refused_and_force_replaces(runner, tmp_path):
    out = tmp_path / "o"
    log = str(SAMPLES / "office" / "office.mcap")
    assert _run(runner, ["run", log, "-o", str(out), "-q"]).exit_code == 0
    result = _run(runner, ["run", log, "-o", str(out), "-q"])
    assert result.exit_code == 1
    assert "earlier sonarmap output" in result.output and "--force" in result.output
    result = _run(runner, ["run", log, "-o", str(out), "-q", "--force"])
    assert result.exit_code == 0, result.output
    assert (out / "map.pgm").exists()
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "keep.txt").write_text("x")
    for force in ([], ["--force"]):
        result = _run(runner, ["run", log, "-o", str(mine), "-q", *force])
        assert result.exit_code == 1 and "is not a sonarmap output" in result.output
        assert "--force" not in result.output
    assert sorted(p.name for p in mine.iterdir()) == ["keep.txt"]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "empty file"),
        (b"\x00\x01garbage\xff" * 10, "unknown log format"),
        (b"#ROSBAG V2.0\n" + b"\x00" * 5, ""),
        (b"\x89MCAP0\r\n\x01\x02", ""),
    ],
    ids=["empty", "garbage", "truncated-bag", "truncated-mcap"],
)
def test_bad_input_exits_1_with_one_line_and_no_output(runner, tmp_path, content, message):
    bad = tmp_path / "bad.log"
    bad.write_bytes(content)
    out = tmp_path / "o"
    result = _run(runner, ["run", str(bad), "-o", str(out), "-q"])
    assert result.exit_code == 1
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("sonarmap: error: ")
    assert "bad.log" in lines[0] and message in lines[0]
    assert "Traceback" not in result.output
    assert not out.exists() and list(tmp_path.iterdir()) == [bad]


def test_compare_correction_reports_both(runner, tmp_path):
    out = tmp_path / "o"
    log = str(SAMPLES / "office" / "office.mcap")
    assert _run(runner, ["run", log, "-o", str(out), "-q", "--compare-correction"]).exit_code == 0
    comp = json.loads((out / "metrics.json").read_text())["comparison"]
    on, off = comp["with_correction"], comp["without_correction"]
    assert on["features_corrected"] > 0 and off["features_corrected"] == 0
    assert on["mean_feature_variance_m2"] != off["mean_feature_variance_m2"]
    assert (out / "map_no_correction.png").exists()
    assert "without feature correction" in (out / "report.md").read_text()


def test_classic_method_has_no_features(runner, tmp_path):
    out = tmp_path / "o"
    log = str(SAMPLES / "office" / "office.mcap")
    assert _run(runner, ["run", log, "-o", str(out), "-q", "--method", "classic"]).exit_code == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["run"]["method"] == "classic" and m["counts"]["features"] == 0
    assert m["map"]["cells_occupied"] > 0


def test_usage_errors_exit_2(runner, tmp_path):
    assert _run(runner, ["run"]).exit_code == 2
    assert _run(runner, ["run", "x", "-o", str(tmp_path / "o"), "--method", "magic"]).exit_code == 2
    assert _run(runner, ["frobnicate"]).exit_code == 2


def test_a_real_subprocess_maps_and_fails_cleanly(tmp_path):
    out = tmp_path / "o"
    ok = subprocess.run(
        [sys.executable, "-m", "cli", "run", str(SAMPLES / "office" / "office.mcap"), "-o", str(out)],
        capture_output=True, text=True, cwd=ROOT, timeout=300,
    )
    assert ok.returncode == 0, ok.stderr
    assert f"outputs in {out}" in ok.stdout
    bad = tmp_path / "empty.bag"
    bad.write_bytes(b"")
    fail = subprocess.run(
        [sys.executable, "-m", "cli", "run", str(bad), "-o", str(tmp_path / "o2")],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )
    assert fail.returncode == 1
    assert fail.stderr.strip().splitlines() == [f"sonarmap: error: {bad}: empty file (0 bytes)"]
