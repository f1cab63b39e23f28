from __future__ import annotations

import itertools
import math
import os

import numpy as np
import pytest

from formats.contract import PoseBatch
from pipeline.stages.pose_sync import (
    AFTER_LAST_POSE,
    BEFORE_FIRST_POSE,
    IN_POSE_GAP,
    MAX_POSE_SPEED_MPS,
    POSE_JUMP,
    POSE_OK,
    STAMP_JITTER_S,
    build_pose_track,
    interpolate_poses,
    is_pose_jump,
    pose_gap_limit_s,
    pose_spikes,
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
    tr = track([t0, t0 + 2], [0.0, 0.5], [0, 0], [0, 0])
    # 0.5 m in 2 ns passes as stamp jitter: only the arithmetic is under test here.
    look = interpolate_poses(tr, np.array([t0 + 1], np.int64), S)
    assert look.reason[0] == POSE_OK
    assert look.x[0] == pytest.approx(0.25)


def test_stamp_jitter_is_not_a_jump_but_a_glitch_is():
    """Real odometry (the Intel lab's ODOM lines): two lines 1 ms apart 6 cm from each other
    are jitter in the stamps; a 19.6 m spike within 0.1 s is a glitch."""
    step = np.array([0.06, 0.9, 1.5, 19.6, 19.6])
    dt = np.array([0.001, 0.0, 0.001, 0.09, 2.0])
    assert is_pose_jump(step, dt).tolist() == [False, False, True, True, False]
    assert pytest.approx(1.0) == STAMP_JITTER_S * MAX_POSE_SPEED_MPS


def test_readings_between_poses_a_robot_cannot_reach_get_pose_jump():
    # 0.1 s apart: 0.5 m is 5 m/s (a robot), 3 m is 30 m/s (a glitch).
    tr = track([0, S // 10, 2 * S // 10], [0.0, 0.5, 3.5], [0, 0, 0], [0, 0, 0])
    t = np.array([S // 20, S // 10, 3 * S // 20], np.int64)
    look = interpolate_poses(tr, t, S)
    assert look.reason.tolist() == [POSE_OK, POSE_OK, POSE_JUMP]  # at a pose stamp: its pose
    assert look.x[0] == pytest.approx(0.25)


def test_a_pose_the_robot_can_neither_reach_nor_leave_is_a_spike():
    t = np.arange(8, dtype=np.int64) * (S // 10)
    x = np.array([0.0, 0.1, 19.7, 0.3, 0.4, 30.0, 30.1, 30.2])
    y = np.zeros(8)
    # Pose 2 is 19.6 m out and back within 0.2 s; pose 5 is a jump to a new place the
    # track stays at (an odometry reset), not a spike; the ends are never spikes.
    assert pose_spikes(t, x, y).tolist() == [False, False, True] + [False] * 5
    x2 = np.array([50.0, 0.1, 0.2, 50.0])  # out at both ends: no neighbour on both sides
    assert not pose_spikes(t[:4], x2, y[:4]).any()
    pair = np.array([0.0, 0.1, 19.7, 19.8, 0.4])  # two glitch poses: not isolated
    assert not pose_spikes(t[:5], pair, y[:5]).any()


def test_a_spike_is_dropped_from_the_track_and_the_readings_beside_it_keep_their_pose():
    t = [0, S // 10, 2 * S // 10, 3 * S // 10]
    tr = track(t, [0.0, 0.1, 19.7, 0.3], [0.0] * 4, [0.0] * 4)
    assert tr.t_ns.tolist() == [0, S // 10, 3 * S // 10] and tr.spikes == 1
    look = interpolate_poses(tr, np.array([2 * S // 10], np.int64), S)
    assert look.reason.tolist() == [POSE_OK] and look.x[0] == pytest.approx(0.2)


def test_pose_gap_limit_adapts_to_the_pose_rate_within_bounds():
    assert pose_gap_limit_s(0.0, 0.9) == pytest.approx(2.7)  # 1 Hz odometry
    assert pose_gap_limit_s(0.0, 0.05) == 0.5  # 20 Hz: the floor
    assert pose_gap_limit_s(0.0, 3.0) == 5.0  # the ceiling
    assert pose_gap_limit_s(0.0, math.nan) == 0.5
    assert pose_gap_limit_s(0.8, 0.05) == 0.8  # set in the configuration: as set


def test_bulk_bounds_leave_isolated_outliers_out():
    n = 1000
    t = [i * S // 20 for i in range(n)]
    x = [0.01 * i for i in range(n)]
    x[500] = x[501] = 2000.0  # two poses 2 km away and back (one alone is a spike)
    tr = track(t, x, [0.0] * n, [0.0] * n)
    box, left_out = tr.bulk_bounds()
    assert box == (0.0, 0.0, pytest.approx(9.99), 0.0) and left_out == 2
    assert tr.bounds()[2] == 2000.0
    assert tr.median_interval_s() == pytest.approx(0.05)


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
    from pipeline.stages.ingest import StampOrder

    order = StampOrder()
    a = make_range_batch([10, 20, 15, 30], [0, 0, 0, 1], 1.0, 0.5, 0.1, 5.0)
    assert order.backwards(a).tolist() == [False, False, True, False]
    # Sensor 1 at 25 < 30 went back; sensor 0 at 21 > 20 did not (15 never raised the max).
    b = make_range_batch([21, 25, 5], [0, 1, 2], 1.0, 0.5, 0.1, 5.0)
    assert order.backwards(b).tolist() == [False, True, False]


def _one_by_one_track(t, x):
    """The filtering of build_pose_track, written as the plain loop it stands for."""
    kept_t, kept_x, running, last, back, dup = [], [], None, None, 0, 0
    for ti, xi in zip(t, x, strict=True):
        if running is not None and ti < running:
            back += 1
        elif last is not None and ti == last:
            dup += 1
        else:
            last = ti
            if math.isfinite(xi):
                kept_t.append(ti)
                kept_x.append(xi)
        running = ti if running is None else max(running, ti)
    return kept_t, kept_x, back, dup


@pytest.mark.parametrize("cuts", [[], [1], [3, 4], [2, 5, 7], list(range(1, 12))])
def test_pose_track_built_batch_by_batch_filters_across_batch_boundaries(cuts):
    # Backwards stamps, duplicates and a NaN pose, some of them right at batch boundaries.
    t = [0, 10, 10, 5, 20, 20, 15, 30, 40, 40, 35, 50]
    x = [0.0, 1.0, 9.0, 9.0, 2.0, 9.0, 9.0, math.nan, 4.0, 9.0, 9.0, 5.0]
    want_t, want_x, want_back, want_dup = _one_by_one_track(t, x)
    assert (want_back, want_dup) == (3, 3)  # the fixture exercises both filters
    edges = [0, *cuts, len(t)]
    batches = [
        PoseBatch(np.array(t[a:b], np.int64), np.array(x[a:b]), np.zeros(b - a), np.zeros(b - a), "odom", "base_link")
        for a, b in itertools.pairwise(edges)
    ]
    tr = build_pose_track(batches)
    assert tr.t_ns.tolist() == want_t
    assert tr.x.tolist() == want_x
    assert (tr.backwards, tr.duplicates) == (want_back, want_dup)
    assert (tr.parent_frame, tr.child_frame) == ("odom", "base_link")


@pytest.mark.parametrize("cuts", [[], [1], [2], [3], [1, 2], [2, 3], [1, 2, 3, 4, 5]])
def test_spikes_are_found_across_batch_boundaries(cuts):
    # Poses 2 and 5 are spikes; the cuts put one before, at or after a batch boundary.
    t = [i * S // 10 for i in range(7)]
    x = [0.0, 0.1, 25.0, 0.3, 0.4, -40.0, 0.6]
    edges = [0, *cuts, len(t)]
    batches = [
        PoseBatch(np.array(t[a:b], np.int64), np.array(x[a:b]), np.zeros(b - a),
                  np.zeros(b - a), "odom", "base_link")
        for a, b in itertools.pairwise(edges)
    ]
    tr = build_pose_track(batches)
    assert tr.x.tolist() == [0.0, 0.1, 0.3, 0.4, 0.6] and tr.spikes == 2


def test_path_length_in_blocks_matches_the_whole_sum():
    n = 200_000  # more than one block of the blockwise sum
    ang = np.linspace(0.0, 40.0 * math.pi, n)
    tr = track(np.arange(n, dtype=np.int64), np.cos(ang), np.sin(ang), np.zeros(n))
    whole = float(np.hypot(np.diff(tr.x), np.diff(tr.y)).sum())
    assert tr.path_length() == pytest.approx(whole, rel=1e-12)
    assert tr.path_length() == pytest.approx(40.0 * math.pi, rel=1e-6)  # 20 laps of a unit circle


def test_built_track_is_mapped_read_only_and_survives_page_release():
    n = 200_000  # several pages and blocks per column
    t = np.arange(n, dtype=np.int64) * 50_000_000
    ang = np.linspace(0.0, 6.0, n)
    tr = track(t, np.cos(ang) * 3.0, np.sin(ang) - 1.0, ang)
    assert tr.x.flags.writeable is False
    with pytest.raises(ValueError):
        tr.x[0] = 1.0
    want = (tr.x.copy(), tr.yaw.copy())
    tr.release_before(int(t[n // 2]))  # as pass 2 does behind its readings
    tr.release_before(None)  # all pages
    np.testing.assert_array_equal(tr.x, want[0])
    np.testing.assert_array_equal(tr.yaw, want[1])
    look = interpolate_poses(tr, np.array([t[10] + 25_000_000, t[-2]], np.int64), S)
    assert look.reason.tolist() == [POSE_OK, POSE_OK]
    assert look.yaw[1] == pytest.approx((ang[-2] + math.pi) % (2 * math.pi) - math.pi)
    x0, y0, x1, y1 = tr.bounds()
    assert (x0, x1) == (float(tr.x.min()), float(tr.x.max()))
    assert (y0, y1) == (float(tr.y.min()), float(tr.y.max()))


def test_empty_track_has_no_poses_and_nan_bounds():
    tr = build_pose_track([])
    assert len(tr) == 0 and tr.path_length() == 0.0
    assert all(math.isnan(v) for v in tr.bounds())
    tr.release_before(None)  # nothing mapped: a no-op


def _rss_file_kb() -> int:
    with open("/proc/self/status", encoding="ascii") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("RssFile:"))


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="needs Linux /proc")
def test_release_gives_back_the_track_pages_again_after_a_full_walk():
    n = 400_000  # 3.2 MB per column, 12.8 MB in all
    tr = track(np.arange(n, dtype=np.int64) * 1000, np.zeros(n) + 1.0, np.zeros(n), np.zeros(n))

    def touch() -> None:
        float(tr.t_ns.sum()) + float(tr.x.sum()) + float(tr.y.sum()) + float(tr.yaw.sum())

    tr.bounds()  # a walk in blocks that releases behind itself, as before pass 2
    for _ in range(2):  # then whole walks (the drawn trajectory) and full releases
        touch()
        high = _rss_file_kb()
        tr.release_before(None)
        assert high - _rss_file_kb() > 10_000
    touch()
    high = _rss_file_kb()
    tr.release_before(int(tr.t_ns[n // 2]))  # half of every column
    assert high - _rss_file_kb() > 5_000


def test_sonar_geometry_at_a_general_heading():
    """A heading where both the sine and the cosine terms count (not a multiple of π/2)."""
    yaw = math.radians(30.0)
    ox, oy, a = sonar_geometry(
        np.array([1.0]), np.array([-2.0]), np.array([yaw]),
        np.array([0.3]), np.array([0.1]), np.array([math.radians(170.0)]),
    )
    c, s = math.cos(yaw), math.sin(yaw)
    assert ox[0] == pytest.approx(1.0 + 0.3 * c - 0.1 * s)  # 1.2098
    assert oy[0] == pytest.approx(-2.0 + 0.3 * s + 0.1 * c)  # -1.7634
    assert a[0] == pytest.approx(math.radians(-160.0))  # 200° wrapped into [-π, π)


def test_pose_track_running_maximum_carries_across_batches():
    """A stamp below an earlier batch's maximum went backwards, even when it rises within
    its own batch."""
    from pipeline.stages.pose_sync import PoseTrackBuilder

    builder = PoseTrackBuilder()
    for t in ([0, 10], [5, 6, 11], [11, 12]):
        n = len(t)
        builder.add(
            PoseBatch(np.array(t, np.int64) * S, np.arange(n, dtype=float), np.zeros(n),
                      np.zeros(n), "odom", "base_link")
        )
    tr = builder.finish()
    assert tr.t_ns.tolist() == [0, 10 * S, 11 * S, 12 * S]
    assert (tr.backwards, tr.duplicates) == (2, 1)


def test_bulk_bounds_join_pieces_across_track_blocks():
    # More poses than one block (65,536): the piece a block starts with continues the
    # previous block's last piece, so the glitch in the first block stays an outlier.
    n = 140_000
    t = np.arange(n, dtype=np.int64) * (S // 20)
    x = np.arange(n) * 1e-4
    x[5000:5003] = 2000.0  # three poses 2 km away and back
    tr = build_pose_track([PoseBatch(t, x, np.zeros(n), np.zeros(n), "odom", "base_link")])
    box, left_out = tr.bulk_bounds()
    assert left_out == 3
    assert box == (0.0, 0.0, pytest.approx((n - 1) * 1e-4), 0.0)
