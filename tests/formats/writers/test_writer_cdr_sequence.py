"""Bulk CDR of marker arrays and paths: byte for byte what rosbags writes, for every
frame-name length (alignment phase) and element count."""

from __future__ import annotations

import numpy as np
import pytest
from writers_helpers import make_features

from formats.writers import map_mcap
from formats.writers.trajectory_tum import Trajectory

FRAMES = ["", "m", "map", "odom", "odom_", "base_l", "base_li", "a_much_longer_frame"]


@pytest.mark.parametrize("n", [0, 1, 2, 9])
@pytest.mark.parametrize("frame", FRAMES)
def test_markers_and_path_equal_rosbags_serialisation(n: int, frame: str) -> None:
    rng = np.random.default_rng(n)
    features = make_features(list(rng.uniform(-5, 50, n)), list(rng.uniform(0, 50, n)),
                             [(0.01, 0.003, 0.02)] * n, list(rng.integers(1, 50, n)))
    traj = Trajectory(np.arange(n, dtype=np.int64) * 50_000_001 + 1_700_000_000_000_000_000,
                      rng.uniform(0, 50, n), rng.uniform(0, 50, n), rng.uniform(-3, 3, n))
    ts = map_mcap._typestore()
    m = map_mcap._Msgs(ts)
    stamp = 1_700_000_123_000_000_456
    cols = map_mcap._marker_columns(features)
    header = m.Header(stamp=map_mcap._stamp(m, stamp), frame_id=frame)
    markers = [map_mcap._marker(m, header, {k: v[i] for k, v in cols.items()}) for i in range(n)]
    expected = bytes(ts.serialize_cdr(m.MarkerArray(markers=markers), map_mcap.MARKERS_TYPE))
    assert map_mcap._markers_cdr(m, features, frame, stamp) == expected
    pcols = map_mcap._pose_columns(traj)
    poses = [map_mcap._pose(m, frame, {k: v[i] for k, v in pcols.items()}) for i in range(n)]
    path = m.Path(header=m.Header(stamp=map_mcap._stamp(m, stamp), frame_id=frame), poses=poses)
    assert map_mcap._path_cdr(m, traj, frame, stamp) == bytes(ts.serialize_cdr(path, map_mcap.PATH_TYPE))
