from __future__ import annotations

import math

import numpy as np
import pytest

from formats.contract import PoseBatch
from pipeline.pose_sync import (
    AFTER_LAST_POSE,
    BEFORE_FIRST_POSE,
    IN_POSE_GAP,
    POSE_OK,
    build_pose_track,
    interpolate_poses,
    sonar_geometry,
)

S = 1_000_000_000


def track(t, x, y, yaw):
    b = PoseBatch(np.array(t, np.int64), np.array(x, float), np.array(y, float), np.array(yaw, float), "odom", "base_link")
    return build_pose_track([b])


def test_linear_position_and_shortest_arc_yaw():
    tr = track([0, S], [0.0, 2.0], [0.0, -1.0], [math.radians(170), math.radians(-170)])
    look = interpolate_poses(tr, np.array([S // 2, S // 4], np.int64), S)
    assert look.reason.tolist() == [POSE_OK, POSE_OK]
    assert look.x == pytest.approx([1.0, 0.5])
    assert look.y == pytest.approx([-0.5, -0.25])
    # Shortest arc through ±180°, not through 0°.
    assert abs(abs(look.yaw[0]) - math.pi) < 1e-9
    assert look.yaw[1] == pytest.approx(math.radians(175))


def test_readings_outside_coverage_and_in_gaps_are_dropped_by_reason():
    tr = track([S, 2 * S, 5 * S, 6 * S], [0, 1, 2, 3], [0, 0, 0, 0], [0, 0, 0, 0])
    t = np.array([0, S, 3 * S, 5 * S, 6 * S, 7 * S], np.int64)
    look = interpolate_poses(tr, t, max_gap_ns=S // 2 * 3)  # 1.5 s allowed, gap is 3 s
    assert look.reason.tolist() == [BEFORE_FIRST_POSE, POSE_OK, IN_POSE_GAP, POSE_OK, POSE_OK, AFTER_LAST_POSE]
    assert look.x[1] == 0 and look.x[3] == 2 and look.x[4] == 3
    assert np.isnan(look.x[[0, 2, 5]]).all()


def test_exact_stamp_at_a_gap_edge_is_not_in_the_gap():
    tr = track([0, 10 * S], [0, 1], [0, 0], [0, 0])
    look = interpolate_poses(tr, np.array([0, 10 * S, 5 * S], np.int64), S)
    assert look.reason.tolist() == [POSE_OK, POSE_OK, IN_POSE_GAP]


def test_backwards_and_duplicate_pose_stamps_are_removed_and_counted():
    tr = track([0, S, S, 3 * S, 2 * S, 4 * S], [0, 1, 9, 3, 9, 4], [0] * 6, [0] * 6)
    assert tr.t_ns.tolist() == [0, S, 3 * S, 4 * S]
    assert tr.x.tolist() == [0, 1, 3, 4]
    assert tr.backwards == 1 and tr.duplicates == 1
    assert tr.path_length() == pytest.approx(4.0)


def test_epoch_stamps_keep_nanosecond_precision():
    t0 = 1_700_000_000 * S
    tr = track([t0, t0 + 2], [0.0, 2.0], [0, 0], [0, 0])
    look = interpolate_poses(tr, np.array([t0 + 1], np.int64), S)
    assert look.x[0] == pytest.approx(1.0)


def test_sonar_geometry_applies_the_mount_in_the_robot_frame():
    ox, oy, a = sonar_geometry(
        np.array([1.0]), np.array([2.0]), np.array([math.pi / 2]),
        np.array([0.1]), np.array([0.2]), np.array([math.radians(-90)]),
    )
    # Robot faces +y: mount x (forward) goes to +y, mount y (left) goes to -x.
    assert ox[0] == pytest.approx(1.0 - 0.2)
    assert oy[0] == pytest.approx(2.0 + 0.1)
    assert a[0] == pytest.approx(0.0)


def test_stamps_going_backwards_are_flagged_per_sensor_across_batches():
    from formats.contract import make_range_batch
    from pipeline.ingest import StampOrder

    order = StampOrder()
    a = make_range_batch([10, 20, 15, 30], [0, 0, 0, 1], 1.0, 0.5, 0.1, 5.0)
    assert order.backwards(a).tolist() == [False, False, True, False]
    # Sensor 1 at 25 < 30 went back; sensor 0 at 21 > 20 did not (15 never raised the max).
    b = make_range_batch([21, 25, 5], [0, 1, 2], 1.0, 0.5, 0.1, 5.0)
    assert order.backwards(b).tolist() == [False, True, False]
