"""The sonar physics model's mechanics on synthetic walls (pipeline.tools.sonar)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from formats.errors import ConfigError
from pipeline.tools.simulate.world import World
from pipeline.tools.sonar import Fan, SonarPhysics, readings
from pipeline.tools.sonar.surfaces import critical_angles, patch_keys
from pipeline.tools.sonar.world_scene import world_fans

# No random errors, one cut-off for every surface (10°): the geometry alone decides.
EXACT = dataclasses.replace(
    SonarPhysics(), critical_angle_median_deg=10.0, critical_angle_spread=0.0,
    level_noise_db=0.0, p_miss=0.0, p_crosstalk=0.0, sigma_d0=0.0, k_d=0.0,
)


def fire(world: World, physics: SonarPhysics = EXACT, *, yaw: float = 0.0, n: int = 1,
         seed: int = 0) -> tuple[np.ndarray, Fan, np.ndarray]:
    """n readings of a sonar at the origin with axis ``yaw``: ranges, fan, ghost flags."""
    z = np.zeros(n)
    fan = world_fans(world, z, z.copy(), z + yaw, z + 5.0, physics, seed=0)
    e = readings(fan, z + 0.1, z + 5.0, physics, np.random.Generator(np.random.PCG64(seed)))
    return e.range_m, fan, e.ghost


def segments(*rows: tuple[float, float, float, float]) -> World:
    return World(np.array(rows, dtype=np.float64), np.empty((0, 3)))


def test_head_on_wall_answers_at_its_distance() -> None:
    r, _, ghost = fire(segments((2.0, -3.0, 2.0, 3.0)))
    assert r[0] == pytest.approx(2.0, abs=1e-5) and not ghost[0]


def test_oblique_smooth_wall_is_silent_but_a_rough_one_answers() -> None:
    # A wall at 45° across the whole beam: every ray meets it 21°+ beyond its 10° cut-off.
    wall = segments((1.0, -1.0, 4.0, 2.0))
    r, fan, _ = fire(wall)
    assert np.isfinite(fan.d1).all() and r[0] == 5.0  # no echo: max range
    rough = dataclasses.replace(EXACT, critical_angle_median_deg=60.0)
    r, _, _ = fire(wall, rough)
    # A rough wall answers from off the axis, nearer than along it (2 m), no nearer than
    # its normal distance (√2 m, at 45° off the axis: outside the audible beam).
    assert math.sqrt(2.0) + 0.05 < r[0] < 1.9


def test_next_surface_answers_behind_a_silent_oblique_one() -> None:
    # A short oblique panel in the left half of the beam at ~1 m, a head-on wall at 3 m.
    world = segments((0.9, 0.05, 1.3, 0.45), (3.0, -3.0, 3.0, 3.0))
    r, fan, ghost = fire(world)
    assert np.nanmin(np.where(np.isfinite(fan.d1), fan.d1, np.nan)) < 1.4  # the panel is in the beam
    assert r[0] == pytest.approx(3.0, abs=1e-5) and not ghost[0]


def test_multipath_ghost_is_longer_than_every_surface_in_the_beam() -> None:
    # Wall A at 45° through (2, 0) mirrors the axis to +y, onto wall B (y = 1.5) head-on:
    # the image of B in A is a wall at x = 3.5, so the ghost reads 2 + 1.5 m.
    world = segments((1.0, -1.0, 3.0, 1.0), (1.0, 1.5, 3.0, 1.5))
    r, fan, ghost = fire(world)
    assert ghost[0]
    assert r[0] == pytest.approx(3.5, abs=0.02)
    assert r[0] > fan.d1[np.isfinite(fan.d1)].max()


def test_beam_pattern_hears_a_pole_on_axis_not_far_off_it() -> None:
    pole = World(np.empty((0, 4)), np.array([[2.0, 0.0, 0.05]]))
    assert fire(pole)[0][0] == pytest.approx(1.95, abs=0.01)
    off = EXACT.audible_half_angle() + math.radians(3)
    assert fire(pole, yaw=off)[0][0] == 5.0


def test_misses_and_crosstalk_counts_and_determinism() -> None:
    wall = segments((2.0, -3.0, 2.0, 3.0))
    noisy = dataclasses.replace(EXACT, p_miss=0.1, p_crosstalk=0.2, sigma_d0=0.01, k_d=0.01)
    n = 4000
    z = np.zeros(n)
    fan = world_fans(wall, z, z.copy(), z, z + 5.0, noisy, seed=0)
    e = readings(fan, z + 0.1, z + 5.0, noisy, np.random.Generator(np.random.PCG64(7)))
    assert abs(int(e.missed.sum()) - 0.1 * n) < 4 * math.sqrt(0.09 * n)
    assert abs(int(e.crosstalk.sum()) - 0.2 * n) < 4 * math.sqrt(0.16 * n)
    # Crosstalk reads before the own echo (or before max range when the echo was missed).
    assert np.all(e.range_m[e.crosstalk] <= 5.0) and np.all(e.range_m[e.crosstalk] >= 0.1)
    clean = ~e.missed & ~e.crosstalk
    assert np.abs(e.range_m[clean] - 2.0).max() < 5 * 0.03
    again = readings(fan, z + 0.1, z + 5.0, noisy, np.random.Generator(np.random.PCG64(7)))
    other = readings(fan, z + 0.1, z + 5.0, noisy, np.random.Generator(np.random.PCG64(8)))
    np.testing.assert_array_equal(e.range_m, again.range_m)
    assert not np.array_equal(e.range_m, other.range_m)


def test_critical_angles_are_a_pure_lognormal_function_of_the_surface() -> None:
    keys = np.arange(20000, dtype=np.int64)
    ph = SonarPhysics()
    a = np.degrees(critical_angles(keys, ph, seed=3))
    np.testing.assert_array_equal(a, np.degrees(critical_angles(keys, ph, seed=3)))
    assert not np.array_equal(a, np.degrees(critical_angles(keys, ph, seed=4)))
    assert np.median(a) == pytest.approx(ph.critical_angle_median_deg, rel=0.03)
    assert np.std(np.log(a)) == pytest.approx(ph.critical_angle_spread, rel=0.05)
    # Points of one patch share a key, hence a finish.
    k = patch_keys(np.array([0.1, 0.9, 1.1]), np.array([0.2, 0.8, 0.2]), 1.0)
    assert k[0] == k[1] != k[2]


def test_parameters_are_validated_and_overridden_by_name() -> None:
    ph = SonarPhysics().with_overrides(["margin_db=30", "p_miss=0.1"])
    assert (ph.margin_db, ph.p_miss) == (30.0, 0.1)
    with pytest.raises(ConfigError, match="p_miss"):
        SonarPhysics().with_overrides(["p_miss=2"])
    with pytest.raises(ConfigError, match="KEY=VALUE"):
        SonarPhysics().with_overrides(["bogus=1"])


def test_emulated_sonar_from_a_laser_scan_of_a_wall() -> None:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "emulate"))
    from emulate_helpers import laser_log, wall_ranges

    from formats.options import MountConfig
    from pipeline.tools.emulate import emulate, ring_from_mounts

    angles = np.arange(-90.0, 90.5, 1.0)
    ring = ring_from_mounts([MountConfig("front", 0.0, 0.0, 0.0, 30.0, 0.1, 5.0),
                             MountConfig("left", 0.0, 0.0, 60.0, 30.0, 0.1, 5.0)])
    log = laser_log(np.stack([wall_ranges(2.0, angles)] * 3), angles)
    em = emulate(log, ring, physics=EXACT, seed=0)
    # Head-on: the wall's distance; at 60° to the wall's normal: silent (max range).
    np.testing.assert_allclose(em.ranges[:, 0], 2.0, atol=1e-5)
    np.testing.assert_array_equal(em.ranges[:, 1], 5.0)
    ideal = emulate(log, ring)
    assert ideal.ranges[0, 1] < 5.0  # the ideal sonar hears the oblique wall


def test_ideal_emulation_of_the_intel_sample_is_the_committed_log(tmp_path: object) -> None:
    from pathlib import Path

    from pipeline.tools.emulate import EmulateOptions, run_emulation

    repo = Path(__file__).resolve().parents[4]
    sample = repo / "sample_logs" / "intel-lab"
    out = Path(str(tmp_path)) / "intel.mcap"
    run_emulation(sample / "intel-corrected.log.gz", out, "mcap",
                  options=EmulateOptions(sonar_model="ideal", compression="zstd"))
    assert out.read_bytes() == (sample / "intel.mcap").read_bytes()
    assert out.with_name("intel.truth.csv").read_bytes() == (sample / "intel.truth.csv").read_bytes()
