"""Finding logs, naming outputs, manifests, summaries and the worker's error recording —
without a cluster."""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from batch_helpers import write_config, write_corrupt_log, write_wall_log

from formats.errors import ConfigError, InputError, OutputError
from pipeline.config import Config, load_config
from pipeline.tools import batch
from pipeline.tools.batch import LogOutcome, find_logs, output_names, read_manifest

ROS1_HEAD = b"#ROSBAG V2.0\n" + b"\0" * 64


def _tree(root: Path) -> None:
    write_wall_log(root / "a.csv")
    write_wall_log(root / "sub" / "deep" / "b.csv", seed=1)
    write_corrupt_log(root / "sub" / "broken.csv")  # a CSV log by its header: taken
    (root / "sub" / "robot.bag").write_bytes(ROS1_HEAD)
    bag2 = root / "bag2"
    (bag2 / "nested").mkdir(parents=True)
    (bag2 / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag2 / "bag2_0.mcap").write_bytes(b"\x89MCAP0\r\n")
    write_wall_log(bag2 / "nested" / "inside.csv")  # inside a bag: not searched
    (root / "README.md").write_text("# logs\nsome words here\n")
    (root / "notes.txt").write_text("just some text, with commas\n")
    (root / "route.waypoints.csv").write_text("x,y\n1.0,1.2\n")
    write_wall_log(root / "sim.truth.csv")
    write_wall_log(root / ".hidden" / "h.csv")
    (root / "empty.csv").write_bytes(b"")
    run_out = root / "old_run"  # an earlier `sonarmap run` output
    run_out.mkdir()
    (run_out / "metrics.json").write_text("{}")
    (run_out / "features.parquet").write_bytes(b"PAR1")
    write_wall_log(run_out / "copy.csv")
    write_wall_log(root / "out" / "x.csv")  # the batch's own output dir


def test_directory_search_takes_logs_and_skips_the_rest(tmp_path: Path) -> None:
    _tree(tmp_path)
    found = find_logs([tmp_path], Config(), exclude=[tmp_path / "out"])
    rel = [p.relative_to(tmp_path).as_posix() for p in found]
    # old_run's metrics.json does not say sonarmap wrote it: its names prove nothing.
    assert rel == ["a.csv", "bag2", "old_run/copy.csv", "sub/broken.csv", "sub/deep/b.csv",
                   "sub/robot.bag"]
    assert all(p.is_absolute() for p in found)


def test_explicit_files_are_taken_as_given_and_deduplicated(tmp_path: Path) -> None:
    _tree(tmp_path)
    a = tmp_path / "a.csv"
    found = find_logs([a, tmp_path / "README.md", a, tmp_path / "missing.bag"], Config())
    assert found == sorted([a, tmp_path / "README.md", tmp_path / "missing.bag"], key=str)


def test_csv_set_directory_is_one_log(tmp_path: Path) -> None:
    s = tmp_path / "set1"
    s.mkdir()
    (s / "ranges.csv").write_text("t,sensor,range\n0,left,1\n")
    (s / "poses.csv").write_text("t,x,y,yaw\n0,0,0,0\n")
    assert find_logs([tmp_path], Config()) == [s]


def test_udacity_sample_set_is_one_log_with_its_config() -> None:
    root = Path(__file__).resolve().parents[4] / "sample_logs"
    sample = root / "udacity-8sonar"
    if not sample.is_dir():
        pytest.skip("sample_logs/udacity-8sonar not present")
    found = find_logs([root], load_config(sample / "sonarmap.toml"))
    assert sample in found  # the set directory, as one log
    assert not [p for p in found if p.is_relative_to(sample) and p != sample]
    assert not [p for p in found if ".truth." in p.name or p.suffix in (".md", ".yaml")]
    # With the default CSV names (ranges.csv/poses.csv) it is not a log set.
    assert sample not in find_logs([root], Config())


def test_manifest_relative_paths_comments_and_blank_lines(tmp_path: Path) -> None:
    write_wall_log(tmp_path / "logs" / "a.csv")
    m = tmp_path / "lists" / "batch.txt"
    m.parent.mkdir()
    m.write_text(f"# two logs\n\n../logs/a.csv\n  {tmp_path / 'abs.csv'}  \n#../no.csv\n")
    assert read_manifest(m) == [m.parent / "../logs/a.csv", tmp_path / "abs.csv"]
    found = find_logs([], Config(), manifests=[m])
    # normalised absolute paths ('..' folded), sorted
    assert found == [tmp_path / "abs.csv", tmp_path / "logs" / "a.csv"]


def test_missing_manifest_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"nope\.txt: manifest not found"):
        read_manifest(tmp_path / "nope.txt")


def test_output_names_disambiguate_equal_names_by_path_hash() -> None:
    a, b, c = Path("/d1/run.csv"), Path("/d2/run.bag"), Path("/d3/other.mcap")
    d = Path("/d4/summary.md.csv")  # stem 'summary.md' would shadow the summary file
    names = output_names([a, b, c, d])
    ha = hashlib.sha256(b"/d1/run.csv").hexdigest()[:8]
    hb = hashlib.sha256(b"/d2/run.bag").hexdigest()[:8]
    hd = hashlib.sha256(b"/d4/summary.md.csv").hexdigest()[:8]
    assert names == {a: f"run-{ha}", b: f"run-{hb}", c: "other", d: f"summary.md-{hd}"}
    assert output_names([c, b, a, d]) == names  # independent of order


def test_summary_files_sorted_rows_and_markdown(tmp_path: Path) -> None:
    rows = [
        LogOutcome("/l/a.csv", "a", "ok", None, 9.9, 300, 38, 0.0025, 10.96, 0.5,
                   warnings="data lost: the log is damaged (bytes lost 1,234)"),
        LogOutcome("/l/b.csv", "b", "failed", "/l/b.csv: line 3: bad | pipe", seconds=0.1),
    ]
    pq_path, md_path = batch.write_summary(tmp_path, rows)
    t = pq.read_table(pq_path)
    assert t.column_names == [
        "path", "name", "status", "error", "duration_s", "readings", "features",
        "mean_feature_variance_m2", "mapped_area_m2", "seconds", "warnings",
    ]
    assert t.to_pylist()[1] == {
        "path": "/l/b.csv", "name": "b", "status": "failed", "error": "/l/b.csv: line 3: bad | pipe",
        "duration_s": None, "readings": None, "features": None,
        "mean_feature_variance_m2": None, "mapped_area_m2": None, "seconds": 0.1,
        "warnings": None,
    }
    md = md_path.read_text()
    assert "2 logs: 1 mapped, 0 skipped (unchanged), 1 failed." in md
    assert ("| a | ok | 9.9 | 300 | 38 | 0.0025 | 10.96 | 0.50 | /l/a.csv |  | data lost: the "
            "log is damaged (bytes lost 1,234) |") in md
    assert "bad \\| pipe |" in md
    first = pq_path.read_bytes()
    batch.write_summary(tmp_path, rows)
    assert pq_path.read_bytes() == first  # deterministic bytes


def test_worker_records_sonarmap_error_as_one_line(tmp_path: Path) -> None:
    log = write_corrupt_log(tmp_path / "bad.csv")
    cfg = load_config(write_config(tmp_path / "c.toml"))
    d = batch._map_one(str(log), str(tmp_path / "out"), "bad", cfg.to_dict(), False)
    assert d["status"] == "failed"
    assert d["error"] == f"{log}: line 3: column 'x': expected a number, found 'zero'"
    assert "traceback" not in d
    assert not (tmp_path / "out" / "bad").exists()
    assert [p.name for p in (tmp_path / "out").iterdir()] == []  # staging removed


def test_worker_records_missing_input(tmp_path: Path) -> None:
    d = batch._map_one(str(tmp_path / "gone.bag"), str(tmp_path), "gone", Config().to_dict(),
                       False)
    assert d["status"] == "failed"
    assert d["error"] == f"{tmp_path / 'gone.bag'}: no such file or directory"


def test_worker_records_unexpected_exception_with_type_and_traceback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    import pipeline.run

    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError("mapper exploded\nsecond line")

    monkeypatch.setattr(pipeline.run, "run", boom)
    log = write_wall_log(tmp_path / "a.csv")
    d = batch._map_one(str(log), str(tmp_path / "out"), "a", Config().to_dict(), False)
    assert d["status"] == "failed"
    assert d["error"] == "RuntimeError: mapper exploded second line"
    assert "Traceback" in d["traceback"] and "boom" in d["traceback"]

    class Done:
        def result(self) -> dict[str, object]:
            return dict(d)

    with caplog.at_level(logging.ERROR, logger="sonarmap.batch"):
        row = batch._collect(Done(), log, "a")
    assert row.error == "RuntimeError: mapper exploded second line"
    assert "unexpected error while mapping" in caplog.text and "in boom" in caplog.text


def test_task_that_dies_on_the_cluster_is_a_failed_row() -> None:
    class Died:
        def result(self) -> None:
            raise OSError("worker lost")

    row = batch._collect(Died(), Path("/l/a.bag"), "a")
    assert (row.status, row.error) == ("failed", "OSError: worker lost")


def test_marker_skip_needs_same_sha_and_config(tmp_path: Path) -> None:
    log = write_wall_log(tmp_path / "a.csv")
    out = tmp_path / "out" / "a"
    out.mkdir(parents=True)
    cfg = Config()
    sha = hashlib.sha256(log.read_bytes()).hexdigest()
    row = {"name": "a", "duration_s": 9.9, "readings": 300, "features": 38,
           "mean_feature_variance_m2": 0.0025, "mapped_area_m2": 10.96}
    marker = {"input_sha256": sha, "config_hash": cfg.hash(), "row": row}
    (out / batch.MARKER).write_text(json.dumps(marker))
    d = batch._map_one(str(log), str(tmp_path / "out"), "a", cfg.to_dict(), False)
    assert d["status"] == "skipped"
    assert (d["readings"], d["features"], d["path"]) == (300, 38, str(log))
    other = cfg.replace(grid=type(cfg.grid)(resolution=0.2))
    d2 = batch._map_one(str(log), str(tmp_path / "out"), "a", other.to_dict(), False)
    assert d2["status"] != "skipped"  # config changed: mapped again (ok or failed)


def test_no_logs_found_is_an_input_error(tmp_path: Path) -> None:
    (tmp_path / "README.md").write_text("# nothing\n")
    with pytest.raises(InputError, match="no logs found in"):
        batch.run_batch([tmp_path], tmp_path / "out", None, workers=1)


def test_whole_batch_problems_raise_before_any_mapping(tmp_path: Path) -> None:
    log = write_wall_log(tmp_path / "a.csv")
    (tmp_path / "out").write_text("a file")
    with pytest.raises(OutputError, match=r"/out: exists and is not a directory$"):
        batch.run_batch([log], tmp_path / "out", None)
    with pytest.raises(ConfigError, match=r"nope\.toml: configuration file not found"):
        batch.run_batch([log], tmp_path / "out2", tmp_path / "nope.toml")
    assert not (tmp_path / "out2").exists()


def test_local_workers_get_a_memory_limit() -> None:
    with batch._client(1, None, "1GiB") as client:
        limits = [w["memory_limit"] for w in client.scheduler_info()["workers"].values()]
    assert limits == [2**30]
    with pytest.raises(ConfigError, match=r"--memory-limit must be 'auto' or a size like 4GB"), \
            batch._client(1, None, "lots"):
        pass
