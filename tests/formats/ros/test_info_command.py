"""`sonarmap info` reports what ROS's own tools report for every real fixture bag."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_ros2_fixture_bags import BOTH
from typer.testing import CliRunner

from cli.app import app

ROS1 = Path(__file__).parents[2] / "data" / "ros1"


def _info(path: Path) -> dict:
    result = CliRunner().invoke(app, ["info", str(path), "--json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
@pytest.mark.parametrize(("folder", "count"), BOTH)
def test_info_counts_of_rosbag2_fixtures(ros2_fixtures: Path, folder: str, count: int, storage: str) -> None:
    info = _info(ros2_fixtures / folder.format(s=storage))
    assert info["message_count"] == count
    assert sum(t["count"] for t in info["topics"]) == count
    assert info["format"] == f"ros2-{storage}"


def test_info_of_ros1_fixtures() -> None:
    tiago = _info(ROS1 / "tiago-sonar.bag")
    assert {t["name"]: t["count"] for t in tiago["topics"]} == {"/sonar_base": 609}
    assert tiago["range_topics"] == ["/sonar_base"]
    lz4, bz2 = _info(ROS1 / "example-lz4.bag"), _info(ROS1 / "example-bz2.bag")
    assert lz4["topics"] == bz2["topics"] and lz4["message_count"] == bz2["message_count"] > 0
    assert _info(ROS1 / "no-messages.bag")["message_count"] == 0


def test_info_on_a_zero_byte_bag_is_one_line_error() -> None:
    result = CliRunner().invoke(app, ["info", str(ROS1 / "empty-file.bag")])
    assert result.exit_code == 1
    assert result.output.strip() == f"sonarmap: error: {ROS1 / 'empty-file.bag'}: empty file (0 bytes)"
