"""`sonarmap run` end to end through the CLI, on every sample log."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from cli.app import app
from formats.writers.nav2_map import load_nav2_map
from pipeline.methods import Method

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_logs"

OUTPUTS = {"map.pgm", "map.yaml", "map.png", "map.mcap", "trajectory.csv", "features.parquet",
           "metrics.json", "config.toml", "report.html", "report.md", ".sonarmap-output"}

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


def test_refine_poses_prints_what_refinement_did(runner, tmp_path):
    # The office sample's poses are true: nothing established, nothing applied, said so.
    log = str(SAMPLES / "office" / "office.mcap")
    result = _run(runner, ["run", log, "-o", str(tmp_path / "out"), "--refine-poses"])
    assert result.exit_code == 0, result.output
    line = next(v for v in result.output.splitlines() if v.startswith("pose refinement:"))
    assert re.fullmatch(r"pose refinement: scale error not established \([+-]\d\.\d% ± "
                        r"\d\.\d%, z \d\.\d < 3, echoes to 5 m\), not applied; no heading bias \(the sharpest, "
                        r"[+-]0\.\d\d°/m, makes the echoes 0\.\d% sharper, < 1%\); graph from "
                        r"the calibration: \d+ submaps, \d+ matches, \d+ loop closures \(\d+ "
                        r"rejected\), not applied: [^;]+; poses moved 0\.00 m mean, "
                        r"0\.00 m max", line), line


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


def test_map_mcap_holds_map_pgm_features_and_trajectory(runner, tmp_path):
    """Read back with the mcap library and rosbags (not sonarmap's readers)."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    out = tmp_path / "o"
    assert _run(runner, ["run", str(SAMPLES / "office" / "office.mcap"), "-o", str(out), "-q"]).exit_code == 0
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with (out / "map.mcap").open("rb") as f:
        msgs = {c.topic: ts.deserialize_cdr(m.data, s.name) for s, c, m in make_reader(f).iter_messages()}
    metrics = json.loads((out / "metrics.json").read_text())
    grid = msgs["/map"]
    frame = metrics["trajectory"]["pose_frames"][0]
    assert frame == "odom" and grid.header.frame_id == frame
    yaml_doc = (out / "map.yaml").read_text()
    assert f"resolution: {grid.info.resolution:.2f}" in yaml_doc
    assert f"origin: [{grid.info.origin.position.x!r}, {grid.info.origin.position.y!r}, 0.0]" in yaml_doc
    pgm = (out / "map.pgm").read_bytes()
    w, h = grid.info.width, grid.info.height
    assert pgm.startswith(f"P5\n{w} {h}\n255\n".encode())
    pixels = np.frombuffer(pgm[-w * h:], np.uint8).reshape(h, w)[::-1]  # PGM row 0 = top
    data = np.asarray(grid.data, np.int8).reshape(h, w)
    assert np.array_equal(data, np.select([pixels == 0, pixels == 254], [100, 0], -1))
    assert int((data == 100).sum()) == metrics["map"]["cells_occupied"] > 0
    table = pq.read_table(out / "features.parquet")
    markers = msgs["/sonar_features"].markers
    assert [m.id for m in markers] == table.column("id").to_pylist()
    sigma = table.column("sigma_major").to_numpy()
    assert np.allclose([m.scale.x for m in markers], np.maximum(4 * sigma, 1e-3))
    poses = msgs["/trajectory"].poses
    assert len(poses) == metrics["counts"]["poses"]
    rows = [ln.split(" ") for ln in (out / "trajectory.csv").read_text().splitlines()[1:]]
    assert len(rows) == metrics["counts"]["poses"]
    assert float(rows[-1][1]) == pytest.approx(poses[-1].pose.position.x, abs=1e-9)


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
        (b"\x00\x01garbage\xff" * 10, "not a recognised log format"),
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


def test_a_log_map_mcap_cannot_stamp_fails_before_it_is_mapped(runner, tmp_path, monkeypatch):
    # The office's CSV set moved past 2^31 s (ROS 2's int32 seconds): refused at ingest,
    # from its poses, in one line naming the log (map.mcap is never written); the mapping
    # pass never starts.
    import pipeline.run

    log = tmp_path / "late"
    log.mkdir()
    for f in (SAMPLES / "office" / "office_csv").iterdir():
        text = f.read_text()
        if f.name != "sensors.csv":
            text = "\n".join(line.replace("1700000", "2200000", 1) if line[:1].isdigit()
                             else line for line in text.splitlines()) + "\n"
        (log / f.name).write_text(text)

    def mapped(*args, **kwargs):
        raise AssertionError("mapped a log whose outputs cannot be written")

    monkeypatch.setattr(pipeline.run, "_map_stream", mapped)
    out = tmp_path / "o"
    result = _run(runner, ["run", str(log), "-o", str(out), "-q"])
    assert result.exit_code == 1, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1
    assert re.search(rf"{re.escape(str(log))}: the log's stamps 2200000000\.000 … 2200000\d{{3}}\.\d{{3}} s \(the map's "
                     r"2200000\d{3}\.\d{3} s\) cannot be written to MCAP: a header stamp holds "
                     r"-2147483648 … 2147483647 s", lines[0]), lines[0]
    assert not out.exists()


def test_a_text_file_is_not_a_recognised_log_format(runner, tmp_path):
    out = tmp_path / "o"
    result = _run(runner, ["run", str(ROOT / "README.md"), "-o", str(out), "-q"])
    assert result.exit_code == 1
    line = result.output.strip()
    assert line.startswith(f"sonarmap: error: {ROOT / 'README.md'}: not a recognised log format")
    for tried in ("ROS 1 bag", "MCAP", "ROS 2 bag", "CSV (a header of column names"):
        assert tried in line
    assert "column" not in line.split("CSV")[0] and "\n" not in line and not out.exists()


def test_run_json_is_one_machine_readable_summary(runner, tmp_path):
    out = tmp_path / "o"
    result = runner.invoke(app, ["run", str(SAMPLES / "office" / "office.mcap"), "-o", str(out),
                                 "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)  # stdout is the JSON alone
    assert doc["out_dir"] == str(out)
    assert set(doc["outputs"]) == OUTPUTS - {".sonarmap-output"}  # the outputs, not the marker
    assert doc["outputs"]["map.mcap"] == str(out / "map.mcap")
    metrics = json.loads((out / "metrics.json").read_text())
    assert doc["counts"]["readings"] == metrics["counts"]["readings"] == 8469
    assert doc["counts"]["readings_used"] == metrics["counts"]["readings_used"]
    assert doc["paper_metric"] == metrics["paper_metric"]
    assert doc["dropped"] == {"max_range": metrics["dropped"]["max_range"]}  # non-zero only
    assert doc["warnings"] == metrics["warnings"] == []


def test_warnings_reach_metrics_and_the_report(runner, tmp_path):
    out = tmp_path / "o"
    cfg = tmp_path / "gap.toml"
    cfg.write_text("[pose_sync]\ntime_offset_s = -5.0\n")  # the first 5 s of readings: no pose
    result = _run(runner, ["run", str(SAMPLES / "office" / "office.mcap"), "-o", str(out), "-c", str(cfg)])
    metrics = json.loads((out / "metrics.json").read_text())
    assert result.exit_code == 0, result.output
    assert metrics["dropped"]["before_first_pose"] > 0.01 * metrics["counts"]["readings"]
    assert metrics["warnings"][0].startswith("readings dropped: ")
    assert "before first pose" in metrics["warnings"][0]
    assert f"warning: {metrics['warnings'][0]}" in result.output
    assert metrics["warnings"][0] in (out / "report.md").read_text()


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
    bad = _run(runner, ["run", "x", "-o", str(tmp_path / "o"), "--method", "magic"])
    assert bad.exit_code == 2
    # The choices are the config's: one definition (pipeline.methods.Method).
    assert ("'magic' is not one of 'specular', 'forward', 'attribution', 'andersone', "
            "'classic'") in bad.output
    assert [m.value for m in Method] == [
        "specular", "forward", "attribution", "andersone", "classic"]
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


def test_evaluate_adds_its_results_to_the_run_report(runner, tmp_path):
    from pipeline.stages.run_report import write_run_reports

    out = tmp_path / "o"
    assert _run(runner, ["run", str(SAMPLES / "office" / "office.mcap"), "-o", str(out), "-q"]).exit_code == 0
    html0, md0 = (out / "report.html").read_bytes(), (out / "report.md").read_bytes()
    # The run's report is exactly what the run directory's files render to.
    copy = tmp_path / "copy"
    copy.mkdir()
    for p in out.iterdir():
        (copy / p.name).write_bytes(p.read_bytes())
    write_run_reports(copy)
    assert (copy / "report.html").read_bytes() == html0 and (copy / "report.md").read_bytes() == md0
    data = {p.name: p.read_bytes() for p in out.iterdir() if not p.name.startswith("report.")}
    truth = SAMPLES / "office" / "office.truth.yaml"
    args = ["evaluate", str(out), "--truth", str(truth)]
    assert _run(runner, [*args, "--no-report"]).exit_code == 0
    assert (out / "report.md").read_bytes() == md0
    result = _run(runner, args)
    assert result.exit_code == 0, result.output
    md = (out / "report.md").read_text()
    assert "## Evaluation" in md and md.index("## Map") < md.index("## Evaluation")
    assert re.search(r"\| Quality \| F1 0\.\d{3} \(precision \d+\.\d %, recall \d+\.\d %\) against ", md)
    assert "<h2>Evaluation</h2>" in (out / "report.html").read_text()
    # Nothing else in the run directory changed.
    assert {p.name: p.read_bytes() for p in out.iterdir() if not p.name.startswith("report.")} == data


def test_progress_has_the_real_total_from_the_first_pass(tmp_path):
    from pipeline.config import Config
    from pipeline.run import run

    calls = []
    result = run(SAMPLES / "office" / "office.mcap", tmp_path / "o", Config(),
                 progress=lambda stage, done, total: calls.append((stage, done, total)))
    readings = result.metrics.counts["readings"]
    stages = [c[0] for c in calls]
    first_mapping = stages.index("mapping")
    assert first_mapping > 0 and set(stages[:first_mapping]) == {"reading"}
    assert stages[-1] == "writing" and stages.count("writing") == 1
    assert set(stages[first_mapping:-1]) == {"mapping"}  # pass 1, pass 2, outputs: never back
    reading = [c for c in calls if c[0] == "reading"]
    assert all(total is None for _s, _d, total in reading)
    assert reading[-1][1] == readings  # pass 1 counted every reading
    mapping = [c for c in calls if c[0] == "mapping"]
    # The default method streams the log five times: the bar's total covers every pass.
    assert {total for _s, _d, total in mapping} == {5 * readings}  # real total from the start
    done = [d for _s, d, _t in mapping]
    assert done == sorted(done) and done[-1] == 5 * readings
    assert any(readings // 2 < d < readings for d in done)  # pass 1 reports as it goes


_FREEZE_PROBE = """
import gc, sys
import pipeline.run
from cli.app import main
seen = []
inner = pipeline.run.run
def run(*a, **k):
    seen.append(gc.get_freeze_count())
    return inner(*a, **k)
pipeline.run.run = run
sys.argv = ["sonarmap", "run", sys.argv[1], "-o", sys.argv[2], "--quiet"]
try:
    main()
finally:
    print("FROZEN_AT_START", seen, file=sys.stderr)
"""


def test_sonarmap_run_starts_with_its_imports_frozen_in_its_own_process_only(
        runner, tmp_path: Path) -> None:
    # sonarmap's own process: the run's full collections skip the imports' objects
    log = str(SAMPLES / "office" / "office.mcap")
    proc = subprocess.run([sys.executable, "-c", _FREEZE_PROBE, log, str(tmp_path / "own")],
                          cwd=ROOT, capture_output=True, text=True, check=True)
    frozen = re.search(r"FROZEN_AT_START \[(\d+)\]", proc.stderr)
    assert frozen is not None and int(frozen.group(1)) > 10_000
    assert (tmp_path / "own" / "map.pgm").exists()
    # a test runner's (or a library user's) process: nothing of its is frozen
    import gc

    before = gc.get_freeze_count()
    result = _run(runner, ["run", log, "-o", str(tmp_path / "lib"), "--quiet"])
    assert result.exit_code == 0, result.output
    assert gc.get_freeze_count() == before
