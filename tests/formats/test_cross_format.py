"""Every reader yields the same stream for the same simulated content.

One simulated run is written with the real writers (rosbags for ROS 1 and ROS 2, the mcap
library for standalone MCAP, our CSV writer) in every format, then read back through
``formats.open_log``: readings, poses and mounts must agree across all of them.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from formats import detect_format, open_log
from formats.contract import MountBatch, PoseBatch, RangeBatch
from formats.log_writers import write_log
from pipeline.config import Config
from pipeline.tools.simulate.simulate import SimOptions, simulate
from pipeline.tools.simulate.world import world_from_dict

CASES = [
    ("ros1", "log.bag", "none", "ros1"),
    ("ros1", "log_bz2.bag", "bz2", "ros1"),
    ("ros1", "log_lz4.bag", "lz4", "ros1"),
    ("ros2", "log_db3", "none", "ros2"),
    ("ros2", "log_db3_zstd", "zstd", "ros2"),
    ("ros2-mcap", "log_ros2mcap", "none", "ros2"),
    ("mcap", "log.mcap", "zstd", "mcap"),
    ("mcap-ros1", "log_ros1.mcap", "lz4", "mcap"),
    ("csv", "log.csv", "none", "csv"),
    ("csv-set", "log_csv", "none", "csv"),
]


@pytest.fixture(scope="module")
def content():
    world = world_from_dict(
        {"segment": [{"from": [0, 0], "to": [6, 0]}, {"from": [6, 0], "to": [6, 4]},
                     {"from": [6, 4], "to": [0, 4]}, {"from": [0, 4], "to": [0, 0]}],
         "circle": [{"center": [3, 2], "radius": 0.3}]}
    )
    sim = simulate(world, np.array([[1.0, 1.0], [5.0, 1.0], [5.0, 3.0]]), SimOptions(sonar_model="ideal", seed=3, ring_rate_hz=5))
    return sim.to_content()


def _read(path: Path):
    with open_log(path, Config()) as reader:
        ranges, poses, mounts = [], [], {}
        for b in reader.batches():
            if isinstance(b, RangeBatch):
                ranges.append(b)
            elif isinstance(b, PoseBatch):
                poses.append(b)
            elif isinstance(b, MountBatch):
                mounts.update(b.mounts)
        names = list(reader.sensor_names)
    r = RangeBatch.concat(ranges)
    sensor = np.array([names[i] for i in r.sensor_id])
    order = np.lexsort((sensor, r.t_ns))
    p_t = np.concatenate([p.t_ns for p in poses])
    keep = np.r_[True, np.diff(p_t) != 0]  # the CSV single layout repeats a pose per row
    pose = {k: np.concatenate([getattr(p, k) for p in poses])[keep] for k in ("t_ns", "x", "y", "yaw")}
    return r.take(order), sensor[order], pose, mounts


@pytest.fixture(scope="module")
def reference(content, tmp_path_factory):
    path = tmp_path_factory.mktemp("ref") / "ref.mcap"
    write_log(content, path, "mcap")
    return _read(path)


@pytest.mark.parametrize(("fmt", "name", "compression", "detected"), CASES, ids=[c[1] for c in CASES])
def test_every_format_reads_back_the_same_stream(content, reference, tmp_path, fmt, name, compression, detected):
    path = write_log(content, tmp_path / name, fmt, compression=compression)
    assert detect_format(path) == detected
    ranges, sensors, poses, mounts = _read(path)
    ref_ranges, ref_sensors, ref_poses, ref_mounts = reference
    assert len(ranges) == len(ref_ranges) == len(content.ranges)
    assert (sensors == ref_sensors).all()
    np.testing.assert_array_equal(ranges.t_ns, ref_ranges.t_ns)
    np.testing.assert_array_equal(ranges.range_m, ref_ranges.range_m)
    np.testing.assert_allclose(ranges.fov_rad, ref_ranges.fov_rad, rtol=1e-6)
    np.testing.assert_allclose(ranges.max_range_m, ref_ranges.max_range_m, rtol=1e-6)
    if fmt == "csv":
        # The single layout carries the pose of each reading, interpolated at its stamp.
        assert len(poses["t_ns"]) > 0
    else:
        np.testing.assert_array_equal(poses["t_ns"], ref_poses["t_ns"])
        for k in ("x", "y", "yaw"):
            np.testing.assert_allclose(poses[k], ref_poses[k], atol=1e-12)
    if fmt != "csv":  # the single-file CSV carries no mounts
        assert set(mounts) == set(ref_mounts) == set(content.sensor_names)
        for k, m in mounts.items():
            r = ref_mounts[k]
            assert (m.x, m.y) == pytest.approx((r.x, r.y), abs=1e-12)
            assert math.isclose(m.yaw, r.yaw, abs_tol=1e-12)
