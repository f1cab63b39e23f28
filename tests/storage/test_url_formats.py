"""Every writer's format read back from S3 gives the stream the local file gives."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from formats import open_log
from formats.contract import PoseBatch, RangeBatch
from formats.log_writers import write_log
from pipeline.config import Config
from pipeline.tools.simulate.simulate import SimOptions, simulate
from pipeline.tools.simulate.world import world_from_dict

CASES = [  # (writer format, name, compression)
    ("ros1", "log_bz2.bag", "bz2"),
    ("ros2", "log_db3_zstd", "zstd"),
    ("ros2-mcap", "log_ros2mcap", "none"),
    ("mcap-ros1", "log_ros1.mcap", "lz4"),
    ("csv", "log.csv", "none"),
]


@pytest.fixture(scope="module")
def content():
    world = world_from_dict({"segment": [{"from": [0, 0], "to": [5, 0]},
                                         {"from": [5, 0], "to": [5, 3]}]})
    sim = simulate(world, np.array([[1.0, 1.0], [4.0, 1.0], [4.0, 2.0]]),
                   SimOptions(seed=5, ring_rate_hz=5))
    return sim.to_content()


def _stream(where) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    with open_log(where, Config()) as reader:
        ranges, poses = [], []
        for b in reader.batches():
            if isinstance(b, RangeBatch):
                ranges.append(b)
            elif isinstance(b, PoseBatch):
                poses.append(b)
        fmt = reader.info().format
    r = RangeBatch.concat(ranges)
    return fmt, r.t_ns, r.range_m, np.concatenate([p.x for p in poses])


@pytest.mark.parametrize(("fmt", "name", "compression"), CASES, ids=[c[1] for c in CASES])
def test_a_format_from_s3_reads_as_from_disk(fmt, name, compression, content, s3, tmp_path):
    fs, bucket = s3
    local = write_log(content, tmp_path / name, fmt, compression=compression)
    key = f"{bucket}/fmt/{Path(local).name}"
    if Path(local).is_dir():
        for f in sorted(Path(local).iterdir()):
            fs.put_file(str(f), f"{key}/{f.name}")
    else:
        fs.put_file(str(local), key)
    want = _stream(local)
    got = _stream(f"s3://{key}")
    assert got[0] == want[0]
    for a, b in zip(got[1:], want[1:], strict=True):
        np.testing.assert_array_equal(a, b)
    assert len(want[1]) > 100
