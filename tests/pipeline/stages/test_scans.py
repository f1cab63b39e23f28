from __future__ import annotations

import math

import numpy as np
import pytest

from formats.contract import PoseBatch
from formats.errors import InputError
from pipeline.config import ScanConfig
from pipeline.mapper.types import Scan, ScanBatch
from pipeline.stages.pose_sync import build_pose_track
from pipeline.stages.scans import ScanBuilder, ScanKeys, motion_boundaries

S = 1_000_000_000


def _track(n=11, step=0.05, turn=0.0):
    t = np.arange(n, dtype=np.int64) * (S // 10)
    x = np.arange(n) * step
    yaw = np.arange(n) * turn
    return build_pose_track([PoseBatch(t, x, np.zeros(n), yaw, "odom", "base_link")])


def _readings(t):
    t = np.asarray(t, np.int64)
    n = len(t)
    z = np.zeros(n)
    return Scan(t, np.zeros(n, np.int32), z + 1, z, z, z, z + 0.5, z + 0.1, z + 5)


def test_time_policy_windows_count_from_the_first_pose():
    keys = ScanKeys(ScanConfig(policy="time", window_s=0.2), _track())
    k = keys.keys(np.array([0, S // 10, S // 5, S // 2], np.int64), np.full(4, -1))
    assert k.tolist() == [0, 0, 1, 2]


def test_motion_policy_starts_a_scan_after_travel_or_turn():
    tr = _track(n=11, step=0.04)  # 4 cm per pose: a new scan after > 10 cm, i.e. every 3 poses
    b = motion_boundaries(tr, 0.10, math.radians(10))
    assert b.tolist() == [3 * S // 10, 6 * S // 10, 9 * S // 10]
    tr2 = _track(n=5, step=0.0, turn=math.radians(6))
    assert motion_boundaries(tr2, 0.10, math.radians(10)).tolist() == [2 * S // 10, 4 * S // 10]


def test_explicit_policy_needs_scan_ids():
    keys = ScanKeys(ScanConfig(policy="explicit"), _track())
    assert keys.keys(np.array([1, 2], np.int64), np.array([7, 8])).tolist() == [7, 8]
    with pytest.raises(InputError, match="scan policy 'explicit' needs a scan id"):
        keys.keys(np.array([1, 2], np.int64), np.array([-1, 8]))


def test_builder_carries_a_scan_across_chunks_and_flushes_it():
    b = ScanBuilder(ScanKeys(ScanConfig(policy="time", window_s=0.2), _track()))
    first = list(b.push(np.full(3, -1), _readings([0, S // 10, S // 5])))
    assert [s.t_ns.tolist() for s in first] == [[0, S // 10]]
    second = list(b.push(np.full(2, -1), _readings([S // 4, S // 2])))
    assert [s.t_ns.tolist() for s in second] == [[S // 5, S // 4]]
    last = list(b.flush())
    assert [s.t_ns.tolist() for s in last] == [[S // 2]]
    assert b.count == 3


def _track_from(t0_s: float, n: int = 11):
    t = round(t0_s * S) + np.arange(n, dtype=np.int64) * (S // 10)
    x = np.arange(n) * 0.04
    return build_pose_track([PoseBatch(t, x, np.zeros(n), np.zeros(n), "odom", "base_link")])


def test_time_windows_start_at_the_first_pose_not_at_zero():
    t0 = 7 * S + 50_000_000  # the track starts at 7.05 s
    keys = ScanKeys(ScanConfig(policy="time", window_s=0.2), _track_from(7.05))
    t = np.array([t0, t0 + S // 5 - 1, t0 + S // 5, t0 + S], np.int64)
    assert keys.keys(t, np.full(4, -1)).tolist() == [0, 0, 1, 5]


def test_motion_keys_change_at_each_boundary_stamp():
    tr = _track_from(2.0)  # 4 cm per pose: boundaries at the 3rd, 6th and 9th pose after
    keys = ScanKeys(ScanConfig(policy="motion", max_travel_m=0.10, max_turn_deg=10.0), tr)
    t0 = 2 * S
    assert keys.boundaries.tolist() == [t0 + 3 * S // 10, t0 + 6 * S // 10, t0 + 9 * S // 10]
    t = np.array([t0, t0 + 3 * S // 10 - 1, t0 + 3 * S // 10, t0 + 7 * S // 10, t0 + S], np.int64)
    assert keys.keys(t, np.full(5, 4)).tolist() == [0, 0, 1, 2, 3]  # scan ids are ignored


def test_one_push_yields_every_complete_scan():
    b = ScanBuilder(ScanKeys(ScanConfig(policy="time", window_s=0.1), _track()))
    t = [0, S // 20, S // 10, 3 * S // 20, S // 5, S // 2]
    scans = list(b.push(np.full(len(t), -1), _readings(t)))
    # Windows 0, 1 and 2 are complete once a reading of window 5 arrives; 5 is kept back.
    assert [s.t_ns.tolist() for s in scans] == [[0, S // 20], [S // 10, 3 * S // 20], [S // 5]]
    assert b.count == 3
    assert [s.t_ns.tolist() for s in b.push(np.full(1, -1), _readings([S]))] == [[S // 2]]
    assert [s.t_ns.tolist() for s in b.flush()] == [[S]] and b.count == 5


def test_a_one_nanosecond_window_keys_every_stamp_apart():
    t0 = 7 * S + 50_000_000
    keys = ScanKeys(ScanConfig(policy="time", window_s=1e-9), _track_from(7.05))
    t = t0 + np.arange(4, dtype=np.int64)
    assert keys.keys(t, np.full(4, -1)).tolist() == [0, 1, 2, 3]


def test_push_batch_is_the_pushed_scans_joined_as_one_batch():
    t = [0, S // 20, S // 10, 3 * S // 20, S // 5, S // 2]
    keys = ScanConfig(policy="time", window_s=0.1)
    one = ScanBuilder(ScanKeys(keys, _track()))
    scans = list(one.push(np.full(len(t), -1), _readings(t)))
    b = ScanBuilder(ScanKeys(keys, _track()))
    batch = b.push_batch(np.full(len(t), -1), _readings(t))
    assert isinstance(batch, ScanBatch) and batch.bounds == [0, 2, 4, 5]
    assert batch.cat.t_ns.tolist() == t[:5]  # the window of S // 2 is kept back
    assert [s.t_ns.tolist() for s in batch] == [s.t_ns.tolist() for s in scans]
    assert b.count == one.count == 3
    # a chunk that only continues the kept-back scan completes none
    assert len(b.push_batch(np.full(1, -1), _readings([S // 2 + 1]))) == 0
    assert len(b.push_batch(np.full(0, -1), _readings([]))) == 0
    assert [s.t_ns.tolist() for s in b.flush()] == [[S // 2, S // 2 + 1]] and b.count == 4
