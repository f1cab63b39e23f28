"""``run``/``info``/``validate`` with several files of one recording: split bags and
separate sonar/odometry bags map to the same bytes as the whole log; files that are not
one recording are refused with one line and exit 1."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from benchmarks.log_parts import (
    Accept,
    anything,
    before,
    split_mcap,
    split_ros1,
    split_ros2,
    topics,
)
from cli.app import app

ROOT = Path(__file__).resolve().parents[2]
OFFICE = ROOT / "sample_logs" / "office"
T0 = 1_700_000_000_000_000_000
S = 1_000_000_000
runner = CliRunner()


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[Path]]:
    """The first 40 s of the office run (MCAP and ROS 1) whole and in parts."""
    d = tmp_path_factory.mktemp("recording")
    first_40s = before(T0 + 40 * S)
    split_mcap(OFFICE / "office.mcap", [(d / "whole.mcap", first_40s)])
    split_mcap(d / "whole.mcap", [(d / "rec_0.mcap", before(T0 + 20 * S)),
                                  (d / "rec_1.mcap", anything())])
    split_mcap(d / "whole.mcap", [(d / "odom.mcap", topics("/odom")),
                                  (d / "sonar.mcap", anything())])
    # Two recorders of one /sonar topic (even and odd sonars), overlapping all along.
    split_mcap(d / "whole.mcap", [(d / "even.mcap", _odd_sonar(False)),
                                  (d / "odd.mcap", anything())], chunk_size=64 * 1024)
    split_ros1(OFFICE / "office.bag", [(d / "whole.bag", first_40s)])
    split_ros1(d / "whole.bag", [(d / "rec_0.bag", before(T0 + 13 * S)),
                                 (d / "rec_1.bag", before(T0 + 26 * S)),
                                 (d / "rec_2.bag", anything())])
    split_ros2(OFFICE / "office_ros2", [(d / "whole_ros2", first_40s)])
    split_ros2(d / "whole_ros2", [(d / "ros2_sonar", topics("/sonar", "/tf_static")),
                                  (d / "ros2_odom", anything())])
    # Another recording of the same robot, a minute later.
    split_mcap(d / "rec_1.mcap", [(d / "later.mcap", anything())], shift_ns=60 * S)
    # The odometry recorded on the topic name the sonar has in the other file.
    split_mcap(d / "odom.mcap", [(d / "odom_on_sonar.mcap", anything())])
    _rename_topic(d / "odom_on_sonar.mcap", "/odom", "/sonar")
    return {
        "whole_mcap": [d / "whole.mcap"],
        "time": [d / "rec_1.mcap", d / "rec_0.mcap"],  # named out of order on purpose
        "topic": [d / "sonar.mcap", d / "odom.mcap"],
        "sensors": [d / "even.mcap", d / "odd.mcap"],
        "whole_bag": [d / "whole.bag"],
        "ros1_split": [d / "rec_0.bag", d / "rec_1.bag", d / "rec_2.bag"],
        "whole_ros2": [d / "whole_ros2"],
        "ros2_topic": [d / "ros2_sonar", d / "ros2_odom"],  # bag directories
        "later": [d / "rec_0.mcap", d / "later.mcap"],
        "clash": [d / "sonar.mcap", d / "odom_on_sonar.mcap"],
    }


def _odd_sonar(odd: bool) -> Accept:
    """Accept the /sonar messages of odd (or even) numbered sonars, and all others."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)

    def accept(topic: str, t: int, data: bytes) -> bool:
        if topic != "/sonar":
            return True
        frame = store.deserialize_cdr(data, "sensor_msgs/msg/Range").header.frame_id
        return (int(frame.rsplit("_", 1)[1]) % 2 == 1) == odd

    return accept


def _rename_topic(path: Path, old: str, new: str) -> None:
    from mcap.reader import make_reader
    from mcap.writer import Writer

    data = path.read_bytes()
    import io

    out = io.BytesIO()
    w = Writer(out)
    w.start(profile="ros2", library="sonarmap tests")
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    for schema, ch, msg in make_reader(io.BytesIO(data)).iter_messages():
        if schema.id not in schemas:
            schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
        if ch.id not in channels:
            channels[ch.id] = w.register_channel(new if ch.topic == old else ch.topic,
                                                 ch.message_encoding, schemas[schema.id])
        w.add_message(channels[ch.id], msg.log_time, msg.data, msg.publish_time)
    w.finish()
    path.write_bytes(out.getvalue())


def _run(paths: list[Path], out: Path) -> None:
    result = runner.invoke(app, ["run", *map(str, paths), "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def runs(logs: dict[str, list[Path]], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("runs")
    names = ("whole_mcap", "time", "topic", "sensors", "whole_bag", "ros1_split", "whole_ros2",
             "ros2_topic")
    for name in names:
        _run(logs[name], d / name)
    return {name: d / name for name in names}


def _metrics(run: Path) -> dict:
    return json.loads((run / "metrics.json").read_text())


@pytest.mark.parametrize(("parts", "whole"), [("time", "whole_mcap"), ("topic", "whole_mcap"),
                                              ("sensors", "whole_mcap"),
                                              ("ros1_split", "whole_bag"),
                                              ("ros2_topic", "whole_ros2")])
def test_the_parts_of_a_recording_map_to_the_bytes_of_the_whole(
    runs: dict[str, Path], parts: str, whole: str
) -> None:
    a, b = runs[whole], runs[parts]
    assert (b / "map.pgm").read_bytes() == (a / "map.pgm").read_bytes()
    assert (b / "map.yaml").read_bytes() == (a / "map.yaml").read_bytes()
    assert (b / "trajectory.csv").read_bytes() == (a / "trajectory.csv").read_bytes()
    fa, fb = pq.read_table(a / "features.parquet"), pq.read_table(b / "features.parquet")
    assert fa.num_rows > 100
    assert fb.equals(fa)  # every feature, column for column
    meta_a, meta_b = dict(fa.schema.metadata), dict(fb.schema.metadata)
    # The only difference: which input the features came from.
    assert meta_b.pop(b"source_sha256") == _metrics(b)["input"]["sha256"].encode()
    meta_a.pop(b"source_sha256")
    assert meta_b == meta_a
    ma, mb = _metrics(a), _metrics(b)
    assert mb["counts"]["readings"] == ma["counts"]["readings"] > 3000
    assert mb["counts"]["readings_used"] == ma["counts"]["readings_used"]
    assert mb["dropped"] == ma["dropped"]


def test_metrics_and_report_list_the_files_in_time_order(
    runs: dict[str, Path], logs: dict[str, list[Path]]
) -> None:
    inp = _metrics(runs["time"])["input"]
    files = inp["files"]
    assert [f["name"] for f in files] == ["rec_0.mcap", "rec_1.mcap"]
    for f in files:
        assert f["sha256"] == hashlib.sha256(Path(f["path"]).read_bytes()).hexdigest()
    assert files[0]["end_ns"] < files[1]["start_ns"] == T0 + 20 * S
    assert sum(f["messages"] for f in files) == _count_messages(logs["whole_mcap"][0])
    assert inp["name"] == "rec_0.mcap + rec_1.mcap"
    assert inp["duplicates_read_once"] == 0
    assert inp["bytes_lost"] == 0 and inp["losses"] == []
    report = (runs["time"] / "report.md").read_text()
    assert "| Files | rec_0.mcap (2023-11-14 22:13:20.000 UTC to " in report
    assert "rec_1.mcap (2023-11-14 22:13:40.000 UTC to " in report


def _count_messages(path: Path) -> int:
    from mcap.reader import make_reader

    with path.open("rb") as f:
        stats = make_reader(f).get_summary().statistics  # type: ignore[union-attr]
    return int(stats.message_count)


def test_the_order_the_files_are_named_in_changes_nothing(
    runs: dict[str, Path], logs: dict[str, list[Path]], tmp_path: Path
) -> None:
    _run(list(reversed(logs["time"])), tmp_path / "again")
    again, first = _metrics(tmp_path / "again"), _metrics(runs["time"])
    again.pop("timing"), first.pop("timing")
    assert again == first
    assert (tmp_path / "again" / "features.parquet").read_bytes() == \
        (runs["time"] / "features.parquet").read_bytes()


@pytest.mark.parametrize(("case", "expected"), [
    ("later", r"rec_0.mcap \(2023-11-14 22:13:20.000-22:13:39.987 UTC\) and \S+later.mcap "
              r"\(2023-11-14 22:14:40.000-22:14:59.987 UTC\) are 60.0 s apart: not one "
              r"recording .*input.max_file_gap_s = 10 s"),
    ("clash", r"topic /sonar is \S+ in \S+ but \S+ in \S+: files of one recording must agree "
              r"on a topic's type"),
    ("formats", r"files of one recording must have one format: \S+whole.mcap is mcap, "
                r"\S+whole.bag is ros1"),
])
@pytest.mark.parametrize("command", ["run", "info", "validate"])
def test_files_that_are_not_one_recording_are_refused(
    logs: dict[str, list[Path]], tmp_path: Path, case: str, expected: str, command: str
) -> None:
    import re

    paths = logs["whole_mcap"] + logs["whole_bag"] if case == "formats" else logs[case]
    out = tmp_path / "out"
    args = [command, *map(str, paths)] + (["-o", str(out)] if command == "run" else [])
    result = runner.invoke(app, args)
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sonarmap: error: ")
    assert re.search(expected, lines[0]), lines[0]
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_larger_gap_limit_accepts_files_a_minute_apart(
    logs: dict[str, list[Path]], tmp_path: Path
) -> None:
    cfg = tmp_path / "gap.toml"
    cfg.write_text("[input]\nmax_file_gap_s = 120\n")
    result = runner.invoke(app, ["info", *map(str, logs["later"]), "-c", str(cfg), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert info["duration_s"] == pytest.approx(100.0, abs=0.1)
    bad = tmp_path / "bad.toml"
    bad.write_text("[input]\nmax_file_gap_s = -1\n")
    result = runner.invoke(app, ["info", *map(str, logs["later"]), "-c", str(bad)])
    assert result.exit_code == 1
    assert "'input.max_file_gap_s' must be in [0, 3.1536e+07] s, got -1.0" in result.stderr


def test_info_lists_every_file_and_counts_the_recording(logs: dict[str, list[Path]]) -> None:
    result = runner.invoke(app, ["info", *map(str, logs["ros1_split"])])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0] == "Files:        3"
    assert [ln.split()[0] for ln in lines[1:4]] == [str(p) for p in logs["ros1_split"]]
    assert "2023-11-14 22:13:20.000-22:13:32." in lines[1]
    whole = runner.invoke(app, ["info", str(logs["whole_bag"][0]), "--json"])
    parts = runner.invoke(app, ["info", *map(str, logs["ros1_split"]), "--json"])
    w, p = json.loads(whole.stdout), json.loads(parts.stdout)
    assert p["message_count"] == w["message_count"]
    assert [(t["name"], t["count"]) for t in p["topics"]] == \
        [(t["name"], t["count"]) for t in w["topics"]]
    assert (p["start_ns"], p["end_ns"]) == (w["start_ns"], w["end_ns"])
    assert [f["message_count"] for f in p["files"]] == [sum(1 for _ in _bag_times(f["path"]))
                                                         for f in p["files"]]


def test_info_says_when_its_counts_may_hold_a_copy_twice(logs: dict[str, list[Path]]) -> None:
    # Two recorders of /sonar all along: info sums the files' counts (it reads no message),
    # so it says so; files one after the other, or on topics of their own, get no note.
    result = runner.invoke(app, ["info", *map(str, logs["sensors"]), "--json"])
    assert result.exit_code == 0, result.output
    notes = json.loads(result.stdout)["notes"]
    assert ("even.mcap and odd.mcap overlap in time on a topic they share: a message stored "
            "in both counts twice in these per-file counts; reading the log keeps one copy "
            "(duplicates_read_once in metrics.json)") in notes
    for pair in ("ros1_split", "topic"):
        result = runner.invoke(app, ["info", *map(str, logs[pair]), "--json"])
        assert not [n for n in json.loads(result.stdout)["notes"] if "overlap in time" in n]


def _bag_times(path: str) -> list[int]:
    from rosbags.rosbag1 import Reader

    with Reader(path) as r:
        return [t for _, t, _ in r.messages()]


def test_validate_checks_the_recording_as_one_log(logs: dict[str, list[Path]]) -> None:
    whole = runner.invoke(app, ["validate", str(logs["whole_mcap"][0]), "--json"])
    parts = runner.invoke(app, ["validate", *map(str, logs["topic"]), "--json"])
    assert whole.exit_code == parts.exit_code == 0, parts.output
    w, p = json.loads(whole.stdout), json.loads(parts.stdout)
    assert p["path"] == " + ".join(str(x) for x in sorted(logs["topic"]))
    assert p["sensors"] == w["sensors"]
    assert p["findings"] == w["findings"]


@pytest.mark.parametrize("command", ["run", "info", "validate"])
def test_help_says_a_log_may_be_several_files(command: str) -> None:
    out = runner.invoke(app, [command, "--help"]).stdout
    assert f"Usage: sonarmap {command} [OPTIONS] LOG...\n" in out
    assert "several files are one recording" in " ".join(out.split())
