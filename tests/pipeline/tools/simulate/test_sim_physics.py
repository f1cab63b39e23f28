"""Sonar physics: cone ray casting, specular cut-off, circles, limits, noise, firing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formats.errors import ConfigError
from pipeline.tools.simulate.sonar import (
    add_sensor_errors,
    cast_rays,
    firing_schedule,
    true_ranges,
)
from pipeline.tools.simulate.world import World

WALL_X2 = World(np.array([[2.0, -10.0, 2.0, 10.0]]), np.empty((0, 3)))


def _one(
    world: World,
    alpha_deg: float,
    *,
    x: float = 0.0,
    y: float = 0.0,
    fov_deg: float = 30.0,
    rmax: float = 5.0,
) -> float:
    return float(
        true_ranges(
            world,
            np.array([x]),
            np.array([y]),
            np.array([math.radians(alpha_deg)]),
            np.array([math.radians(fov_deg)]),
            np.array([rmax]),
        )[0]
    )


def test_wall_at_normal_incidence_returns_its_distance() -> None:
    assert _one(WALL_X2, 0.0) == pytest.approx(2.0, abs=1e-12)
    # From 0.5 m further back the wall is 2.5 m away.
    assert _one(WALL_X2, 0.0, x=-0.5) == pytest.approx(2.5, abs=1e-12)


def test_oblique_wall_echo_is_the_closest_ray_below_cutoff() -> None:
    # Axis 40° off the normal: rays span 25°…55° incidence, all below 60°; the ray at
    # 25° is the closest (rays are exactly 1° apart across a 30° cone).
    assert _one(WALL_X2, 40.0) == pytest.approx(2.0 / math.cos(math.radians(25.0)), rel=1e-12)
    # Axis 70° off: rays at 55°…85°; only 55°…60° return, the closest at 55°.
    assert _one(WALL_X2, 70.0) == pytest.approx(2.0 / math.cos(math.radians(55.0)), rel=1e-12)


def test_wall_at_grazing_incidence_beyond_cutoff_is_lost() -> None:
    # Axis 80° off the normal: every ray is at 65°…95°, beyond the 60° cut-off.
    assert _one(WALL_X2, 80.0, rmax=50.0) == math.inf
    # A lower cut-off loses the 40° case too.
    d = true_ranges(
        WALL_X2,
        np.zeros(1),
        np.zeros(1),
        np.radians([40.0]),
        np.radians([30.0]),
        np.array([5.0]),
        specular_cutoff_rad=math.radians(20.0),
    )
    assert d[0] == math.inf


def test_grazing_surface_in_front_occludes_the_wall_behind() -> None:
    # A wall along the beam axis's direction (y = 0.3, x from 0.5 to 10) is hit at grazing
    # incidence by the upper rays, which are lost; lower rays reach the wall at x = 2.
    w = World(np.array([[2.0, -10.0, 2.0, 10.0], [0.5, 0.3, 10.0, 0.3]]), np.empty((0, 3)))
    dist, cos_inc = cast_rays(w, np.zeros(2), np.zeros(2), np.radians([10.0, -10.0]))
    assert dist[0] == pytest.approx(0.3 / math.sin(math.radians(10.0)))
    assert cos_inc[0] == pytest.approx(math.sin(math.radians(10.0)))
    assert dist[1] == pytest.approx(2.0 / math.cos(math.radians(10.0)))
    assert cos_inc[1] == pytest.approx(math.cos(math.radians(10.0)))
    # The reading is still the wall at x = 2 (axis ray), not the grazing wall.
    assert _one(w, 0.0) == pytest.approx(2.0)


def test_circle_echo_and_off_axis_trunk() -> None:
    trunk = World(np.empty((0, 4)), np.array([[3.0, 0.0, 0.2]]))
    assert _one(trunk, 0.0) == pytest.approx(2.8, abs=1e-12)
    # A trunk 9.46° off the axis is inside the 15° half-cone. Rays are cast at whole
    # degrees; the echo is the nearest ray hit: along-ray projection minus the half chord.
    off = World(np.empty((0, 4)), np.array([[3.0, 0.5, 0.1]]))
    hits = []
    for deg in range(-15, 16):
        a = math.radians(deg)
        along = 3.0 * math.cos(a) + 0.5 * math.sin(a)
        perp = abs(-3.0 * math.sin(a) + 0.5 * math.cos(a))
        if perp < 0.1:
            hits.append(along - math.sqrt(0.1**2 - perp**2))
    assert len(hits) >= 2
    assert _one(off, 0.0) == pytest.approx(min(hits), abs=1e-12)
    assert min(hits) == pytest.approx(math.hypot(3.0, 0.5) - 0.1, abs=0.005)
    # Outside the cone: nothing.
    assert _one(off, -20.0) == math.inf
    # The wall behind the trunk is farther: the trunk wins.
    both = World(np.array([[4.0, -5.0, 4.0, 5.0]]), np.array([[3.0, 0.0, 0.2]]))
    assert _one(both, 0.0) == pytest.approx(2.8, abs=1e-12)


def test_beyond_max_range_is_no_echo() -> None:
    assert _one(WALL_X2, 0.0, rmax=1.5) == math.inf


def test_sensor_errors_limits_and_rep117() -> None:
    rng = np.random.Generator(np.random.PCG64(3))
    d_true = np.array([0.05, np.inf, 1.0, 4.999])
    d = add_sensor_errors(
        d_true,
        np.full(4, 0.1),
        np.full(4, 5.0),
        rng,
        sigma_d0=0.0,
        k_d=0.0,
        p_miss=0.0,
        p_crosstalk=0.0,
    )
    # Too close → −inf (REP 117), no echo → exactly r_max, noise-free echoes as float32.
    assert d[0] == -math.inf
    assert d[1] == 5.0
    assert d[2] == 1.0
    assert d[3] == float(np.float32(4.999))


def test_noise_statistics_and_clipping() -> None:
    rng = np.random.Generator(np.random.PCG64(7))
    n = 20000
    d_true = np.full(n, 2.0)
    d = add_sensor_errors(
        d_true,
        np.full(n, 0.1),
        np.full(n, 5.0),
        rng,
        sigma_d0=0.01,
        k_d=0.01,
        p_miss=0.0,
        p_crosstalk=0.0,
    )
    sigma = 0.01 + 0.01 * 2.0
    assert abs(d.mean() - 2.0) < 4 * sigma / math.sqrt(n)
    assert d.std() == pytest.approx(sigma, rel=0.05)
    # Large noise is clipped into [r_min, r_max].
    wide = add_sensor_errors(
        d_true,
        np.full(n, 1.9),
        np.full(n, 2.1),
        rng,
        sigma_d0=1.0,
        k_d=0.0,
        p_miss=0.0,
        p_crosstalk=0.0,
    )
    assert wide.min() == pytest.approx(1.9) and wide.max() == pytest.approx(2.1)


def test_missed_echoes_and_crosstalk_fractions() -> None:
    rng = np.random.Generator(np.random.PCG64(11))
    n = 20000
    d = add_sensor_errors(
        np.full(n, 3.0),
        np.full(n, 0.2),
        np.full(n, 5.0),
        rng,
        sigma_d0=0.0,
        k_d=0.0,
        p_miss=0.1,
        p_crosstalk=0.2,
    )
    missed = d == 5.0
    short = d < 3.0 - 1e-6
    assert missed.mean() == pytest.approx(0.1 * 0.8, abs=0.01)  # crosstalk overrides a miss
    # Crosstalk hits 20 % of readings; a missed one (5 m) only reads short below 3 m with
    # probability 2.8/4.8.
    assert short.mean() == pytest.approx(0.2 * (0.9 + 0.1 * 2.8 / 4.8), abs=0.01)
    assert d[short].min() >= 0.2 and d[short].max() < 5.0
    # Crosstalk on a non-missed reading lies in [r_min, d).
    assert d[short & ~missed].max() < 3.0
    # Untouched readings: neither missed nor crosstalk.
    assert (d == 3.0).mean() == pytest.approx(0.9 * 0.8, abs=0.01)


def test_firing_schedule_ring_order_and_period() -> None:
    t, s = firing_schedule(16, 10.0, 1_000, 1_000 + 200_000_000)
    # One sonar every 1/(10·16) s = 6.25 ms, end included.
    assert t.dtype == np.int64 and s.dtype == np.int32
    assert t.shape == (33,)
    np.testing.assert_array_equal(np.diff(t), 6_250_000)
    np.testing.assert_array_equal(s[:18], [*range(16), 0, 1])
    assert t[0] == 1_000 and t[-1] == 1_000 + 200_000_000
    with pytest.raises(ConfigError, match="ring_rate_hz must be > 0"):
        firing_schedule(16, 0.0, 0, 10)


