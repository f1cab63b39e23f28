"""map.mcap read back with the mcap library's reader and rosbags' typestore (not sonarmap's
own readers): schemas, encodings, the grid cell for cell against map.pgm, markers, path."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore
from writers_helpers import make_features

from formats.map_types import GridSpec
from formats.writers.map_mcap import measured_colours, write_map_mcap
from formats.writers.nav2_map import write_nav2_map
from formats.writers.trajectory_tum import Trajectory

GRID = GridSpec(origin_x=-1.5, origin_y=2.25, resolution=0.05, width=4, height=3)
# Row 0 = min y. Distinct classes in every row so a flipped grid cannot pass.
PROB = np.array(
    [
        [0.9, 0.1, np.nan, 0.5],
        [0.1, 0.1, 0.9, np.nan],
        [np.nan, 0.9, 0.9, 0.0],
    ],
    dtype=np.float32,
)
TRAJ = Trajectory(
    np.array([1_700_000_000_000_000_000, 1_700_000_000_500_000_000], dtype=np.int64),
    np.array([0.0, 0.5]), np.array([2.5, 2.6]), np.array([0.0, math.pi / 2]),
)
STAMP = 1_700_000_001_250_000_000


def _read(path: Path) -> tuple[Any, dict[str, tuple[Any, Any, Any]]]:
    ts = get_typestore(Stores.ROS2_HUMBLE)
    out = {}
    with path.open("rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        for schema, channel, message in reader.iter_messages():
            msg = ts.deserialize_cdr(message.data, schema.name)
            out[channel.topic] = (schema, channel, message, msg)
    return header, out


@pytest.fixture
def written(tmp_path: Path, features) -> tuple[Path, Any, dict[str, Any]]:
    path = tmp_path / "map.mcap"
    write_map_mcap(path, probability=PROB, grid=GRID, features=features, trajectory=TRAJ,
                   frame_id="odom", stamp_ns=STAMP)
    header, topics = _read(path)
    return path, header, topics


def test_ros2_profile_embedded_schemas_and_cdr(written) -> None:
    _path, header, topics = written
    assert header.profile == "ros2"
    assert {t: (s.name, s.encoding, c.message_encoding) for t, (s, c, _m, _x) in topics.items()} == {
        "/map": ("nav_msgs/msg/OccupancyGrid", "ros2msg", "cdr"),
        "/sonar_features": ("visualization_msgs/msg/MarkerArray", "ros2msg", "cdr"),
        "/trajectory": ("nav_msgs/msg/Path", "ros2msg", "cdr"),
    }
    # The embedded definition carries its dependencies (a reader needs no installed types).
    grid_schema = topics["/map"][0].data.decode()
    assert "MSG: nav_msgs/MapMetaData" in grid_schema and "int8[] data" in grid_schema
    for _s, channel, message, _msg in topics.values():
        assert message.log_time == message.publish_time == STAMP
        assert "durability: 1" in channel.metadata["offered_qos_profiles"]  # latched


def test_grid_is_map_pgm_cell_for_cell(written, tmp_path: Path) -> None:
    _path, _h, topics = written
    grid = topics["/map"][3]
    assert grid.header.frame_id == "odom"
    assert (grid.header.stamp.sec, grid.header.stamp.nanosec) == (1_700_000_001, 250_000_000)
    assert (grid.info.width, grid.info.height) == (4, 3)
    assert grid.info.resolution == pytest.approx(0.05)
    assert (grid.info.origin.position.x, grid.info.origin.position.y) == (-1.5, 2.25)
    data = np.asarray(grid.data, dtype=np.int8).reshape(3, 4)
    # OccupancyGrid row 0 is the bottom (min y): the same orientation as the probability.
    assert data.tolist() == [[100, 0, -1, -1], [0, 0, 100, -1], [-1, 100, 100, 0]]
    write_nav2_map(tmp_path / "map.yaml", PROB, GRID)
    raw = (tmp_path / "map.pgm").read_bytes()
    pgm = np.frombuffer(raw[-12:], dtype=np.uint8).reshape(3, 4)[::-1]  # PGM row 0 = top
    expected = np.select([pgm == 0, pgm == 254], [100, 0], -1)
    assert np.array_equal(data, expected)


def test_one_2_sigma_cylinder_per_feature_coloured_by_measurements(written, features) -> None:
    _path, _h, topics = written
    markers = topics["/sonar_features"][3].markers
    assert [m.id for m in markers] == features.id.tolist()
    assert {(m.ns, m.type, m.action, m.header.frame_id) for m in markers} == {
        ("sonar_features", 3, 0, "odom")
    }
    # Feature 1: cov diag(0.04, 0.01) → σ 0.2 / 0.1 m, major along x.
    m0 = markers[0]
    assert (m0.pose.position.x, m0.pose.position.y) == (1.0, 0.5)
    assert (m0.scale.x, m0.scale.y) == pytest.approx((0.8, 0.4))
    assert (m0.pose.orientation.z, m0.pose.orientation.w) == pytest.approx((0.0, 1.0))
    # Feature 2: diag(0.01, 0.04) → major along y: turned by 90°.
    assert markers[1].pose.orientation.z == pytest.approx(math.sin(math.pi / 4))
    assert (markers[1].scale.x, markers[1].scale.y) == pytest.approx((0.8, 0.4))
    # measured 5, 1, 9: the most measured is yellow, the one measured once dark purple.
    colours = [(m.color.r, m.color.g, m.color.b) for m in markers]
    assert colours[2] == pytest.approx((0.993, 0.906, 0.144), abs=1e-6)
    assert colours[1] == pytest.approx((0.267, 0.005, 0.329), abs=1e-6)
    assert colours[1][1] < colours[0][1] < colours[2][1]


def test_path_holds_every_pose_with_its_stamp(written) -> None:
    _path, _h, topics = written
    path = topics["/trajectory"][3]
    assert path.header.frame_id == "odom"
    assert [(p.header.stamp.sec, p.header.stamp.nanosec) for p in path.poses] == [
        (1_700_000_000, 0), (1_700_000_000, 500_000_000)]
    assert [(p.pose.position.x, p.pose.position.y) for p in path.poses] == [(0.0, 2.5), (0.5, 2.6)]
    q = path.poses[1].pose.orientation
    assert 2 * math.atan2(q.z, q.w) == pytest.approx(math.pi / 2)


def test_bytes_depend_only_on_the_inputs(tmp_path: Path, features) -> None:
    paths = [tmp_path / "a.mcap", tmp_path / "b.mcap"]
    for p in paths:
        write_map_mcap(p, probability=PROB, grid=GRID, features=features, trajectory=TRAJ,
                       frame_id="", stamp_ns=STAMP)
    assert paths[0].read_bytes() == paths[1].read_bytes()
    _h, topics = _read(paths[0])
    assert topics["/map"][3].header.frame_id == "map"  # a log without a frame name


@pytest.mark.parametrize(("trajectory_s", "stamp_s", "shown"), [
    ((2**31 - 1, 2**31), 2**31, "2147483647.000 … 2147483648.000 s (the map's 2147483648.000 s)"),
    ((-3.0, -1.0), -0.5, "-3.000 … -0.500 s (the map's -0.500 s)"),
])
def test_stamps_the_messages_cannot_carry_are_refused(tmp_path: Path, features,
                                                     trajectory_s: tuple[float, float],
                                                     stamp_s: float, shown: str) -> None:
    from formats.errors import OutputError

    t = np.array([round(v * 1e9) for v in trajectory_s], dtype=np.int64)
    path = tmp_path / "map.mcap"
    with pytest.raises(OutputError, match=rf"map\.mcap: stamps {re.escape(shown)} cannot be "
                                          r"written to MCAP: a header stamp holds -2147483648 "
                                          r"… 2147483647 s \(ROS 2's int32 seconds\), a log "
                                          r"time no negative one$"):
        write_map_mcap(path, probability=PROB, grid=GRID, features=features,
                       trajectory=Trajectory(t, TRAJ.x, TRAJ.y, TRAJ.yaw), frame_id="odom",
                       stamp_ns=round(stamp_s * 1e9))
    assert not path.exists()  # nothing half-written


def test_poses_before_zero_are_written_with_a_log_time_after_it(tmp_path: Path,
                                                               features) -> None:
    # A CSV log stamped from -100 s: its header stamps are negative, its map's (its end) not.
    t = np.array([-100_000_000_000, -99_500_000_000], dtype=np.int64)
    path = tmp_path / "map.mcap"
    write_map_mcap(path, probability=PROB, grid=GRID, features=features,
                   trajectory=Trajectory(t, TRAJ.x, TRAJ.y, TRAJ.yaw), frame_id="odom",
                   stamp_ns=5_000_000_000)
    _h, topics = _read(path)
    poses = topics["/trajectory"][3].poses
    assert [(p.header.stamp.sec, p.header.stamp.nanosec) for p in poses] == [
        (-100, 0), (-100, 500_000_000)]


def test_no_features_gives_an_empty_marker_array(tmp_path: Path) -> None:
    empty = make_features(x=[], y=[], cov=[], measured=[])
    write_map_mcap(tmp_path / "m.mcap", probability=PROB, grid=GRID, features=empty,
                   trajectory=TRAJ, frame_id="odom", stamp_ns=STAMP)
    _h, topics = _read(tmp_path / "m.mcap")
    assert topics["/sonar_features"][3].markers == []


def test_measured_colours_log_scale() -> None:
    c = measured_colours([1, 10, 100])
    assert c[0] == pytest.approx([0.267, 0.005, 0.329])
    assert c[2] == pytest.approx([0.993, 0.906, 0.144])
    assert c[1] == pytest.approx([0.128, 0.567, 0.551])  # log-midway = the middle stop
    assert measured_colours([1, 1]).tolist() == [[0.267, 0.005, 0.329]] * 2
    assert measured_colours([4, 4]).tolist() == [[0.993, 0.906, 0.144]] * 2


def test_rosbags_anyreader_reads_it_from_the_embedded_schemas(written) -> None:
    """rosbags' AnyReader without a typestore: the types come from the file's schemas."""
    from rosbags.highlevel import AnyReader

    path, _h, _t = written
    with AnyReader([path]) as reader:
        msgs = {c.topic: reader.deserialize(raw, c.msgtype) for c, _t, raw in reader.messages()}
    assert np.asarray(msgs["/map"].data).reshape(3, 4).tolist()[0] == [100, 0, -1, -1]
    assert len(msgs["/sonar_features"].markers) == 3
    assert len(msgs["/trajectory"].poses) == 2


def test_odometry_path_is_written_only_when_given(tmp_path: Path, features) -> None:
    odometry = Trajectory(TRAJ.t_ns, TRAJ.x * 1.03, TRAJ.y + 0.1, TRAJ.yaw)
    path = tmp_path / "map.mcap"
    write_map_mcap(path, probability=PROB, grid=GRID, features=features, trajectory=TRAJ,
                   frame_id="odom", stamp_ns=STAMP, odometry=odometry)
    _header, topics = _read(path)
    assert set(topics) == {"/map", "/sonar_features", "/trajectory", "/odometry"}
    schema, _channel, message, msg = topics["/odometry"]
    assert schema.name == "nav_msgs/msg/Path" and message.log_time == STAMP
    assert msg.header.frame_id == "odom"
    assert [(p.pose.position.x, p.pose.position.y) for p in msg.poses] == [
        (0.0, pytest.approx(2.6)), (pytest.approx(0.515), pytest.approx(2.7))]
