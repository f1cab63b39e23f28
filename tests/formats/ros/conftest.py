"""Shared fixtures: the rosbag2 test bags (unpacked once) and bags written here."""

from __future__ import annotations

import io
import tarfile
from pathlib import Path

import pytest
import zstandard

ARCHIVE = Path(__file__).parents[2] / "data" / "ros2" / "ros2-fixtures.tar.zst"


@pytest.fixture(scope="session")
def ros2_fixtures(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Root of the unpacked rosbag2 test resources (see tests/data/ros2/SOURCE.md)."""
    root = tmp_path_factory.mktemp("ros2-fixtures")
    data = zstandard.ZstdDecompressor().stream_reader(ARCHIVE.open("rb")).read()
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        tar.extractall(root, filter="data")
    return root
