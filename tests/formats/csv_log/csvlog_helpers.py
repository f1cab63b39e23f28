"""Helpers of the CSV reader tests: write a log into tmp_path, read it back whole."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from formats.contract import ALL_KINDS, MountBatch, PoseBatch, RangeBatch, SensorMount
from formats.csv_log import CsvLogReader
from pipeline.config import Config, config_from_dict


def make_config(csv: dict[str, Any] | None = None, sensors: dict[str, Any] | None = None) -> Config:
    """A Config with the given [input.csv] and [sensors] tables."""
    data: dict[str, Any] = {"input": {"csv": csv or {}}}
    if sensors is not None:
        data["sensors"] = sensors
    return config_from_dict(data)


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def read_all(
    path: Path, config: Config
) -> tuple[RangeBatch, PoseBatch | None, dict[str, SensorMount], list[str]]:
    """All ranges, all poses (concatenated), the mounts and the sensor names of a log."""
    ranges: list[RangeBatch] = []
    poses: list[PoseBatch] = []
    mounts: dict[str, SensorMount] = {}
    with CsvLogReader(path, config) as reader:
        for b in reader.batches(ALL_KINDS):
            if isinstance(b, RangeBatch):
                ranges.append(b)
            elif isinstance(b, PoseBatch):
                poses.append(b)
            elif isinstance(b, MountBatch):
                mounts.update(b.mounts)
        names = list(reader.sensor_names)
    pose = None
    if poses:
        pose = PoseBatch(
            np.concatenate([p.t_ns for p in poses]),
            np.concatenate([p.x for p in poses]),
            np.concatenate([p.y for p in poses]),
            np.concatenate([p.yaw for p in poses]),
            poses[0].parent_frame,
            poses[0].child_frame,
        )
    return RangeBatch.concat(ranges), pose, mounts, names
