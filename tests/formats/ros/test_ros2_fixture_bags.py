"""The rosbag2 test bags: message counts, topic ids from storage, same bytes in both storages."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from mcap.reader import make_reader

from formats.errors import FormatError
from formats.ros.mcap_source import McapSource
from formats.ros.ros2bag import Ros2BagSource
from formats.ros.source import RawBatch

PY = "rosbag2_py/test/resources"
TESTS = "rosbag2_tests/resources"
TRANSPORT = "rosbag2_transport/test/resources"

# (folder under {storage}, expected messages) for bags present in both storages.
BOTH = [
    (f"{PY}/{{s}}/talker", 20),
    (f"{PY}/{{s}}/convert_a", 150),
    (f"{PY}/{{s}}/convert_b", 75),
    (f"{PY}/{{s}}/wbag", 6074),
    (f"{TESTS}/{{s}}/cdr_test", 7),
    (f"{TESTS}/{{s}}/wrong_rmw_test", 7),
    (f"{TESTS}/{{s}}/bag_with_topics_and_service_events", 10),
    (f"{TRANSPORT}/{{s}}/rewriter_a", 150),
    (f"{TRANSPORT}/{{s}}/rewriter_b", 75),
    (f"{TRANSPORT}/{{s}}/test_bag_for_seek", 5),
]


def _all(src: Ros2BagSource | McapSource) -> list[RawBatch]:
    return list(src.raw_batches([c.id for c in src.connections]))


def _messages(src: Ros2BagSource | McapSource) -> list[tuple[str, int, bytes]]:
    return [
        (b.connection.topic, int(b.log_time_ns[i]), b.message(i))
        for b in _all(src)
        for i in range(len(b))
    ]


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
@pytest.mark.parametrize(("folder", "count"), BOTH)
def test_fixture_counts(ros2_fixtures: Path, folder: str, count: int, storage: str) -> None:
    with Ros2BagSource(ros2_fixtures / folder.format(s=storage)) as src:
        assert src.format_name == f"ros2-{storage}"
        assert sum(c.count for c in src.connections) == count
        assert sum(len(b) for b in _all(src)) == count
        assert src.warnings == []


def test_empty_bag(ros2_fixtures: Path) -> None:
    with Ros2BagSource(ros2_fixtures / "ros2bag/test/resources/empty_bag") as src:
        assert [(c.id, c.topic, c.count) for c in src.connections] == [
            (1, "/rosout", 0),
            (2, "/parameter_events", 0),
        ]
        assert _all(src) == []
        assert src.start_ns is None and src.end_ns is None


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_topic_ids_come_from_storage(ros2_fixtures: Path, storage: str) -> None:
    # metadata.yaml lists /topic first; the storage gives it id 3 (rosbags 0.11 reads 0 here).
    with Ros2BagSource(ros2_fixtures / PY / storage / "talker") as src:
        by_topic = {c.topic: (c.id, c.count, c.msgtype) for c in src.connections}
        assert by_topic == {
            "/rosout": (1, 10, "rcl_interfaces/msg/Log"),
            "/parameter_events": (2, 0, "rcl_interfaces/msg/ParameterEvent"),
            "/topic": (3, 10, "std_msgs/msg/String"),
        }
        topic = [b for b in src.raw_batches([3])]
        assert sum(len(b) for b in topic) == 10
        assert {b.connection.topic for b in topic} == {"/topic"}
        assert src.start_ns == 1585866235112411371
        assert src.end_ns == 1585866239643508139


def test_sqlite_and_mcap_hold_the_same_messages(ros2_fixtures: Path) -> None:
    for name in ("talker", "wbag", "convert_b"):
        with Ros2BagSource(ros2_fixtures / PY / "sqlite3" / name) as a:
            sq = sorted(_messages(a))
        with Ros2BagSource(ros2_fixtures / PY / "mcap" / name) as b:
            mc = sorted(_messages(b))
        assert sq == mc, name


def test_split_bag_merges_topics_with_different_ids(ros2_fixtures: Path) -> None:
    # wbag_0.db3 has AAA=1 ... HHH=8, the later files HHH=1 ... AAA=8.
    with Ros2BagSource(ros2_fixtures / PY / "sqlite3" / "wbag") as src:
        counts = {c.topic: (c.id, c.count) for c in src.connections}
        assert counts["AAA"] == (1, 804)
        assert counts["HHH"] == (8, 726)
        aaa = [b for b in src.raw_batches([1])]
        assert {b.connection.topic for b in aaa} == {"AAA"}
        assert sum(len(b) for b in aaa) == 804
        times = [int(t) for b in aaa for t in b.log_time_ns]
        assert times == sorted(times)
        assert (src.start_ns, src.end_ns) == (1000, 2998)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_split_bag_without_metadata_is_read_in_name_order(
    ros2_fixtures: Path, tmp_path: Path, storage: str
) -> None:
    src_dir = ros2_fixtures / PY / storage / "reindex_test_bags" / "multiple_files"
    assert not (src_dir / "metadata.yaml").exists()
    with Ros2BagSource(src_dir) as src:
        assert [(c.topic, c.count) for c in src.connections] == [("/chatter", 3177)]
        times = [int(t) for b in _all(src) for t in b.log_time_ns]
        assert len(times) == 3177 and times == sorted(times)


def test_single_storage_files(ros2_fixtures: Path) -> None:
    bags = ros2_fixtures / "rosbag2_cpp/test/rosbag2_cpp/bags"
    with Ros2BagSource(bags / "topics_and_services.db3") as a:
        assert a.format_name == "ros2-sqlite3"
        counts = {c.topic: c.count for c in a.connections}
        assert a.connections[0].msgdef_format == "ros2msg"  # message_definitions table
        assert "builtin_interfaces/Time stamp" in a.connections[0].msgdef
    with Ros2BagSource(bags / "topics_and_services.mcap") as b:
        assert b.format_name == "ros2-mcap"
        assert {c.topic: c.count for c in b.connections} == counts
    assert counts["/parameter_events"] == 7
    assert counts["/add_two_ints/_service_event"] == 6
    assert sum(counts.values()) == 13


def test_old_sqlite_schema_has_no_msgdef(ros2_fixtures: Path) -> None:
    with Ros2BagSource(ros2_fixtures / TRANSPORT / "sqlite3" / "test_bag_for_seek") as src:
        (conn,) = src.connections
        # 'test_msgs/BasicTypes' in the storage: normalised, no definition stored.
        assert (conn.msgtype, conn.msgdef, conn.encoding) == ("test_msgs/msg/BasicTypes", "", "cdr")


def test_wrong_serialization_format_is_listed_not_cdr(ros2_fixtures: Path) -> None:
    with Ros2BagSource(ros2_fixtures / TESTS / "mcap" / "wrong_rmw_test") as src:
        assert {c.encoding for c in src.connections} == {"other"}


def test_mcap_source_matches_mcap_library(ros2_fixtures: Path) -> None:
    for path in sorted(ros2_fixtures.rglob("*.mcap")):
        with path.open("rb") as fh:
            ref = sorted(
                (ch.topic, m.log_time, m.data) for _, ch, m in make_reader(fh).iter_messages()
            )
        with McapSource(path) as src:
            assert sorted(_messages(src)) == ref, path.name
            assert src.warnings == []
            # Finalised files are read through their Message Index records.
            assert src.message_indexed, path.name


def test_missing_storage_file(ros2_fixtures: Path, tmp_path: Path) -> None:
    bag = tmp_path / "talker"
    shutil.copytree(ros2_fixtures / PY / "sqlite3" / "talker", bag)
    (bag / "talker.db3").unlink()
    with pytest.raises(FormatError, match=r"talker\.db3.*talker\.db3 listed in the bag is missing"):
        Ros2BagSource(bag)
