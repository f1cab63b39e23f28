"""Sonar emulation on synthetic laser scans: cones, max range, ring selection, content."""

from __future__ import annotations

import math

import numpy as np
import pytest
from emulate_helpers import laser_log, wall_ranges

from formats.contract import SensorMount
from formats.errors import ConfigError, InputError
from formats.options import MountConfig
from formats.presets import PRESETS
from pipeline.tools.emulate import (
    SonarRing,
    cone_coverage,
    emulate,
    emulate_ranges,
    laser_view,
    ring_from_mounts,
)

ANGLES = -90.0 + np.arange(180.0)  # a CARMEN front laser: −90° + i·1°
PIONEER = ring_from_mounts(PRESETS["pioneer-p3dx"])


def one_sonar(fov_deg: float = 30.0, rmin: float = 0.1, rmax: float = 5.0) -> SonarRing:
    return ring_from_mounts(
        [
            MountConfig(
                name="s", x=0.0, y=0.0, yaw_deg=0.0, fov_deg=fov_deg, min_range=rmin, max_range=rmax
            )
        ]
    )


def test_wall_two_metres_ahead_forward_sonars_read_it() -> None:
    log = laser_log([wall_ranges(2.0, ANGLES)], ANGLES)
    em = emulate(log, PIONEER)
    r = dict(zip(em.ring.names, em.ranges[0].tolist(), strict=True))
    # sonar_3/4 sit at x = 0.166 m with axes ±10°: the wall's perpendicular foot is in
    # their cone, so they read the perpendicular distance 2 − 0.166 m (1° beam spacing).
    assert r["sonar_3"] == pytest.approx(1.834, abs=2e-3)
    assert r["sonar_4"] == pytest.approx(1.834, abs=2e-3)
    # sonar_2 (axis 30°, cone 15…45°) sees the wall at 15° from its origin at best.
    assert r["sonar_2"] == pytest.approx((2.0 - 0.148) / math.cos(math.radians(15)), abs=0.02)
    # Side sonars (±90°, cone reaching 75°) read the wall at ~7.4 m: beyond 5 m → max range.
    assert r["sonar_0"] == 5.0
    assert r["sonar_7"] == 5.0


def test_point_just_outside_the_cone_is_ignored() -> None:
    ring = one_sonar()
    angles = [14.5, 15.5]
    inside = laser_log([[1.0, np.nan]], angles)
    outside = laser_log([[np.nan, 1.0]], angles)
    both = laser_log([[3.0, 1.0]], angles)
    assert emulate_ranges(inside, ring)[0, 0] == pytest.approx(1.0, abs=1e-12)
    assert emulate_ranges(outside, ring).tolist() == [[5.0]]
    assert emulate_ranges(both, ring)[0, 0] == pytest.approx(3.0, abs=1e-12)


def test_no_return_reads_max_range_and_too_close_reads_neg_inf() -> None:
    ring = one_sonar()
    angles = [-5.0, 0.0, 5.0]
    no_return = laser_log([[30.0, 31.0, np.inf]], angles, range_max=30.0)  # >= laser max
    beyond = laser_log([[6.0, 7.0, 8.0]], angles)  # echoes beyond the sonar's 5 m
    close = laser_log([[0.05, 2.0, np.nan]], angles)  # closer than the sonar's 0.1 m
    below_laser_min = laser_log([[0.05, 2.0, 2.5]], angles, range_min=0.1)
    assert emulate_ranges(no_return, ring).tolist() == [[5.0]]
    assert emulate_ranges(beyond, ring).tolist() == [[5.0]]
    assert emulate_ranges(close, ring).tolist() == [[-np.inf]]
    assert emulate_ranges(below_laser_min, ring).tolist() == [[2.0]]


def test_laser_offset_moves_endpoints_into_the_base_frame() -> None:
    # The laser 0.5 m ahead of the base, the wall 2 m ahead of the base.
    mount = SensorMount(0.5, 0.0, 0.0)
    log = laser_log([wall_ranges(2.0, ANGLES, mount_x=0.5)], ANGLES, mount=mount)
    em = emulate(log, PIONEER)
    r = dict(zip(em.ring.names, em.ranges[0].tolist(), strict=True))
    assert r["sonar_3"] == pytest.approx(1.834, abs=2e-3)
    assert r["sonar_4"] == pytest.approx(1.834, abs=2e-3)


def test_rear_sonars_not_emitted_and_side_cones_reported() -> None:
    log = laser_log([wall_ranges(2.0, ANGLES)], ANGLES)
    em = emulate(log, PIONEER)
    assert em.ring.names == tuple(f"sonar_{i}" for i in range(8))
    assert em.dropped == tuple(f"sonar_{i}" for i in range(8, 16))
    assert any("not emitted: sonar_8" in n for n in em.notes)
    assert any("sonar_0 49%" in n and "sonar_7 46%" in n for n in em.notes)
    full = emulate(log, PIONEER, require_full_cone=True)
    assert full.ring.names == tuple(f"sonar_{i}" for i in range(1, 7))


def test_cone_coverage_and_view() -> None:
    log = laser_log([wall_ranges(2.0, ANGLES)], ANGLES)
    lo, hi = laser_view(log)
    assert (math.degrees(lo), math.degrees(hi)) == pytest.approx((-90.5, 89.5))
    cov, axis = cone_coverage(PIONEER, SensorMount(0, 0, 0), (lo, hi))
    assert axis.tolist() == [True] * 8 + [False] * 8
    np.testing.assert_array_equal(cov[1:7], 1.0)
    assert 0.4 < cov[0] < 0.6
    assert cov[8:].max() < 0.5
    # A 360° laser sees every cone.
    cov360, axis360 = cone_coverage(PIONEER, SensorMount(0, 0, 0), (-math.pi, math.pi))
    assert axis360.all() and (cov360 == 1.0).all()


def test_emulated_content_columns() -> None:
    walls = [wall_ranges(2.0, ANGLES), wall_ranges(1.0, ANGLES)]
    log = laser_log(walls, ANGLES, poses=[(0.0, 0.0, 0.0), (1.0, 0.5, 0.2)])
    em = emulate(log, PIONEER)
    rb = em.content.ranges
    assert len(rb) == 16
    assert rb.t_ns.tolist() == [1 * 10**9] * 8 + [2 * 10**9] * 8
    assert rb.sensor_id.tolist() == list(range(8)) * 2
    assert rb.scan_id.tolist() == [0] * 8 + [1] * 8
    np.testing.assert_allclose(rb.fov_rad, math.radians(30.0))
    np.testing.assert_array_equal(rb.max_range_m, 5.0)
    np.testing.assert_array_equal(rb.min_range_m, 0.1)
    assert rb.range_m[8 + 3] == pytest.approx(0.834, abs=2e-3)
    assert em.content.sensor_names == em.ring.names
    p = em.content.poses
    assert (p.parent_frame, p.child_frame) == ("map", "base_link")
    assert p.x.tolist() == [0.0, 1.0] and p.yaw.tolist() == [0.0, 0.2]
    m = em.content.mounts["sonar_1"]
    assert (m.x, m.y, m.yaw) == pytest.approx((0.114, 0.119, math.radians(50)))


def test_overrides_and_ring_errors() -> None:
    ring = ring_from_mounts(PRESETS["pioneer-p3dx"], fov_deg=20.0, max_range=3.0)
    np.testing.assert_allclose(ring.fov, math.radians(20.0))
    np.testing.assert_array_equal(ring.max_range, 3.0)
    log = laser_log([wall_ranges(4.0, ANGLES)], ANGLES)
    assert emulate(log, ring).ranges[0, 3] == 3.0  # wall beyond the 3 m override
    # Mount values of 0 ("from the log") take the defaults.
    bare = ring_from_mounts([MountConfig(name="b", yaw_deg=0.0)])
    assert (math.degrees(bare.fov[0]), bare.max_range[0], bare.min_range[0]) == pytest.approx(
        (30.0, 5.0, 0.0)
    )
    with pytest.raises(ConfigError, match=r"fov_deg must be in \(0, 180\)"):
        ring_from_mounts(PRESETS["pioneer-p3dx"], fov_deg=0.0)
    with pytest.raises(ConfigError, match=r"no sonar mounts"):
        ring_from_mounts([])
    with pytest.raises(
        ConfigError, match=r"sonar_0: min range 0.1 m is not below max range 0.05 m"
    ):
        ring_from_mounts(PRESETS["pioneer-p3dx"], max_range=0.05)
    rear_only = ring_from_mounts(PRESETS["pioneer-p3dx"][8:])
    with pytest.raises(
        InputError, match=r"no sonar of the ring lies inside the laser's field of view"
    ):
        emulate(log, rear_only)


def test_matches_brute_force_on_random_scans() -> None:
    rng = np.random.default_rng(7)
    ranges = rng.uniform(0.05, 8.0, size=(6, 180))
    ranges[rng.random(ranges.shape) < 0.1] = 81.83
    log = laser_log(ranges, ANGLES, mount=SensorMount(0.05, -0.02, 0.01), range_max=81.83)
    em = emulate(log, PIONEER)
    ring = em.ring
    for s in range(6):
        for k in range(len(ring)):
            best = math.inf
            for b in range(180):
                r = ranges[s, b]
                if r >= 81.83:
                    continue
                a = math.radians(ANGLES[b]) + 0.01
                px, py = 0.05 + r * math.cos(a), -0.02 + r * math.sin(a)
                dx, dy = px - ring.x[k], py - ring.y[k]
                bearing = (math.atan2(dy, dx) - ring.yaw[k] + math.pi) % (2 * math.pi) - math.pi
                if abs(bearing) <= ring.fov[k] / 2:
                    best = min(best, math.hypot(dx, dy))
            want = -math.inf if best < 0.1 else min(best, 5.0)
            assert em.ranges[s, k] == pytest.approx(want, rel=1e-12)
