"""Logs read from URLs map to the same bytes as the same logs on disk (loopback servers)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml
import zstandard
from typer.testing import CliRunner

from cli.app import app

ROOT = Path(__file__).resolve().parents[2]
OFFICE = ROOT / "sample_logs" / "office"
runner = CliRunner()


def _ros2_db3(dst: Path) -> Path:
    """The office ROS 2 bag with an uncompressed .db3 (sqlite needs a local file)."""
    src = OFFICE / "office_ros2"
    dst.mkdir()
    with (src / "office_ros2.db3.zstd").open("rb") as fin, \
            (dst / "office_ros2.db3").open("wb") as fout:
        zstandard.ZstdDecompressor().copy_stream(fin, fout)
    meta = yaml.safe_load((src / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    info["compression_mode"], info["compression_format"] = "", ""
    info["relative_file_paths"] = ["office_ros2.db3"]
    for f in info["files"]:
        f["path"] = "office_ros2.db3"
    (dst / "metadata.yaml").write_text(yaml.safe_dump(meta))
    return dst


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("logs")
    shutil.copytree(OFFICE / "office_csv", d / "office_csv")
    return {"mcap": OFFICE / "office.mcap", "ros1": OFFICE / "office.bag",
            "ros2": _ros2_db3(d / "office_ros2"), "csv": d / "office_csv"}


def _run(log: str, out: str, *extra: str) -> dict:
    result = runner.invoke(app, ["run", log, "-o", out, "-q", *extra])
    assert result.exit_code == 0, result.output
    return {}


@pytest.fixture(scope="module")
def local_maps(logs: dict[str, Path], tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("local")
    maps = {}
    for name, p in logs.items():
        _run(str(p), str(out / name))
        maps[name] = out / name
    return maps


def _put(fs, local: Path, key: str) -> None:
    if local.is_dir():
        for f in sorted(local.iterdir()):
            fs.put_file(str(f), f"{key}/{f.name}")
    else:
        fs.put_file(str(local), key)


@pytest.mark.parametrize("fmt", ["ros1", "ros2", "csv"])
def test_a_log_on_s3_maps_to_the_same_bytes(fmt, logs, local_maps, s3, tmp_path):
    """ROS 1 bag (ranged reads), ROS 2 bag directory as a prefix (.db3 downloaded to a
    temporary file), CSV log set as a prefix: map.pgm and the input's sha256 as on disk."""
    fs, bucket = s3
    _put(fs, logs[fmt], f"{bucket}/logs/{logs[fmt].name}")
    url = f"s3://{bucket}/logs/{logs[fmt].name}"
    _run(url, str(tmp_path / "out"))
    assert (tmp_path / "out" / "map.pgm").read_bytes() == \
        (local_maps[fmt] / "map.pgm").read_bytes()
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    local = json.loads((local_maps[fmt] / "metrics.json").read_text())
    assert m["input"]["sha256"] == local["input"]["sha256"]
    assert m["input"]["path"] == url


def test_an_mcap_over_http_is_read_by_ranges_through_a_bounded_cache(
        logs, local_maps, http, http_root, tmp_path):
    """64 KiB blocks, 2 cached: every GET of the log is a Range request of one block, and
    the map is the local one's."""
    shutil.copy(logs["mcap"], http_root / "office.mcap")
    cfg = tmp_path / "small.toml"
    cfg.write_text("[storage]\nblock_size_mib = 0.0625\ncache_blocks = 2\n")
    start = len(http.requests)
    _run(f"{http.url}/office.mcap", str(tmp_path / "out"), "-c", str(cfg))
    assert (tmp_path / "out" / "map.pgm").read_bytes() == \
        (local_maps["mcap"] / "map.pgm").read_bytes()
    gets = [r for r in http.requests[start:] if r[0] == "GET" and r[1] == "/office.mcap"]
    assert gets and all(r[2] is not None for r in gets), gets[:3]
    spans = []
    for _, _, rng in gets:
        a, b = rng.removeprefix("bytes=").split("-")
        spans.append(int(b) - int(a) + 1)
    assert max(spans) <= 65536
    size = logs["mcap"].stat().st_size
    assert len(gets) >= size // 65536  # the whole log, block by block


def test_info_says_a_db3_is_downloaded_and_the_copy_is_removed(logs, s3, tmp_path, monkeypatch):
    fs, bucket = s3
    _put(fs, logs["ros2"], f"{bucket}/bag")
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    result = runner.invoke(app, ["info", f"s3://{bucket}/bag"])
    assert result.exit_code == 0, result.output
    assert "office_ros2.db3: a sqlite3 storage file is read from a local copy" in result.output
    assert "removed when closed" in result.output
    assert list(tmp_path.iterdir()) == []  # the temporary copy is gone


def test_several_files_of_one_recording_may_be_urls(logs, s3):
    """A recording named as a URL and a local file: both are read as files of one log."""
    fs, bucket = s3
    _put(fs, logs["ros1"], f"{bucket}/a/office.bag")
    result = runner.invoke(app, ["info", f"s3://{bucket}/a/office.bag", str(logs["ros1"])])
    assert result.exit_code == 0, result.output
    assert "Files:        2" in result.output
    assert f"s3://{bucket}/a/office.bag" in result.output


def test_validate_reads_a_log_from_a_url(logs, s3):
    fs, bucket = s3
    _put(fs, logs["ros1"], f"{bucket}/v/office.bag")
    result = runner.invoke(app, ["validate", f"s3://{bucket}/v/office.bag", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["ok"] is True
    assert report["path"] == f"s3://{bucket}/v/office.bag"
