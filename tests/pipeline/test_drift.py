"""The odometry drift model (pipeline.drift) and its use by simulate and emulate."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from formats.errors import ConfigError
from pipeline.drift import DriftModel, apply_drift

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools" / "emulate"))


def straight(n: int = 11, step: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.arange(n) * step
    return x, np.zeros(n), np.zeros(n)


def test_zero_model_returns_the_truth_as_copies() -> None:
    x, y, yaw = straight()
    ox, oy, oyaw = apply_drift(x, y, yaw, DriftModel())
    assert np.array_equal(ox, x) and np.array_equal(oy, y) and np.array_equal(oyaw, yaw)
    assert ox is not x


def test_scale_error_stretches_every_step() -> None:
    x, y, yaw = straight()
    ox, oy, oyaw = apply_drift(x, y, yaw, DriftModel(scale_error=0.03))
    np.testing.assert_allclose(ox, 1.03 * x, atol=1e-12)
    np.testing.assert_allclose(oy, 0.0, atol=1e-12)
    np.testing.assert_allclose(oyaw, 0.0, atol=1e-12)


def test_heading_bias_turns_the_heading_by_degrees_per_metre() -> None:
    x, y, yaw = straight(n=11, step=1.0)  # 10 m straight ahead
    ox, oy, oyaw = apply_drift(x, y, yaw, DriftModel(heading_bias_deg_per_m=0.8))
    np.testing.assert_allclose(np.degrees(oyaw), 0.8 * np.arange(11), atol=1e-9)
    # Each 1 m step goes along the heading before it: step k at (k-1)*0.8 degrees.
    ang = np.radians(0.8 * np.arange(10))
    np.testing.assert_allclose(ox[-1], np.cos(ang).sum(), atol=1e-12)
    np.testing.assert_allclose(oy[-1], np.sin(ang).sum(), atol=1e-12)
    assert ox[0] == 0.0 and oy[0] == 0.0  # starts where the truth starts


def test_noise_is_seeded_and_needs_a_generator() -> None:
    x, y, yaw = straight()
    m = DriftModel(noise_xy=0.02, noise_yaw=0.01)
    a = apply_drift(x, y, yaw, m, np.random.Generator(np.random.PCG64(7)))
    b = apply_drift(x, y, yaw, m, np.random.Generator(np.random.PCG64(7)))
    c = apply_drift(x, y, yaw, m, np.random.Generator(np.random.PCG64(8)))
    assert all(np.array_equal(p, q) for p, q in zip(a, b, strict=True))
    assert not np.array_equal(a[1], c[1])
    with pytest.raises(ValueError, match="random generator"):
        apply_drift(x, y, yaw, m)


@pytest.mark.parametrize(("kw", "key"), [
    ({"scale_error": 0.7}, "scale_error"),
    ({"heading_bias_deg_per_m": math.nan}, "heading_bias_deg_per_m"),
    ({"noise_xy": -1.0}, "noise_xy"),
])
def test_validate_names_the_parameter(kw: dict[str, float], key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        DriftModel(**kw).validate()


def test_simulate_drifts_the_log_and_keeps_the_truth() -> None:
    from pipeline.tools.simulate import SimOptions, simulate
    from pipeline.tools.simulate.world import world_from_dict

    world = world_from_dict({"polygon": [{"points": [[0, 0], [8, 0], [8, 4], [0, 4]]}]})
    wp = [[1.0, 2.0], [7.0, 2.0]]
    clean = simulate(world, wp, SimOptions(sonar_model="ideal", seed=3))
    drifted = simulate(world, wp, SimOptions(sonar_model="ideal", seed=3, drift_scale=0.03,
                                             drift_heading_bias_deg_per_m=0.8))
    for a in ("t_ns", "x", "y", "yaw"):
        assert np.array_equal(getattr(clean.true_poses, a), getattr(drifted.true_poses, a))
    assert np.array_equal(clean.ranges.range_m, drifted.ranges.range_m)
    # 6 m driven: 3 % longer, heading 4.8 degrees off at the end.
    travelled = np.hypot(drifted.poses.x[-1] - 1.0, drifted.poses.y[-1] - 2.0)
    assert travelled == pytest.approx(6.0 * 1.03, rel=2e-3)
    assert math.degrees(drifted.poses.yaw[-1]) == pytest.approx(4.8, abs=0.05)
    with pytest.raises(ConfigError, match="scale_error"):
        SimOptions(sonar_model="ideal", drift_scale=0.9).validate()


def test_emulation_with_drift_keeps_the_poses_as_truth() -> None:
    from emulate_helpers import laser_log

    from formats.presets import PRESETS
    from pipeline.tools.emulate import emulate, ring_from_mounts

    poses = [(0.1 * k, 0.0, 0.0) for k in range(21)]
    log = laser_log(np.full((21, 181), 3.0), np.linspace(-90, 90, 181), poses=poses)
    ring = ring_from_mounts(PRESETS["pioneer-p3dx"])
    em = emulate(log, ring)
    assert em.with_drift(DriftModel(), 0) is em
    drifted = em.with_drift(DriftModel(scale_error=0.05), 0)
    assert drifted.truth is not None
    np.testing.assert_array_equal(drifted.truth.x, em.content.poses.x)
    np.testing.assert_allclose(drifted.content.poses.x, 1.05 * em.content.poses.x, atol=1e-12)
    assert np.array_equal(drifted.ranges, em.ranges)
    assert "odometry drifted" in drifted.notes[-1]


def test_many_models_at_once_give_the_same_bits_as_one_at_a_time() -> None:
    from pipeline.drift import Steps

    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 20.0, 200)
    x, y, yaw = 2 * np.cos(0.3 * t), np.sin(0.5 * t), np.unwrap(0.4 * t) + 0.1 * rng.random(200)
    steps = Steps.of(x, y, yaw)
    models = [DriftModel(0.03, 0.8), DriftModel(), DriftModel(-0.021, -1.3), DriftModel(0.0, 0.4)]
    many = steps.drifted_many(models)
    for j, model in enumerate(models):
        one = apply_drift(x, y, yaw, model)
        for a, b in zip(one, many, strict=True):
            assert a.tobytes() == b[j].tobytes()
    assert many[0].shape == (4, 200)
    assert np.array_equal(many[0][1], x)  # the zero model: the poses themselves


def test_the_newer_terms_at_zero_draw_what_the_model_drew_before_them() -> None:
    n = 200
    x, y, yaw = np.linspace(0, 20, n), np.zeros(n), np.zeros(n)
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    apply_drift(x, y, yaw, DriftModel(0.03, 0.8, 0.01, 0.01), rng_a)
    rng_b.standard_normal((3, n - 1))  # the one draw of the four-term model
    assert rng_a.random() == rng_b.random()


def test_the_heading_walk_grows_as_the_root_of_the_distance() -> None:
    n = 401
    x, y, yaw = np.linspace(0, 100, n), np.zeros(n), np.zeros(n)
    ends = [apply_drift(x, y, yaw, DriftModel(heading_walk=0.01),
                        np.random.default_rng(s))[2][-1] for s in range(300)]
    assert np.std(ends) == pytest.approx(0.01 * 10, rel=0.15)


def test_slips_turn_the_heading_only_where_they_happen() -> None:
    n = 1001
    x, y, yaw = np.linspace(0, 100, n), np.zeros(n), np.zeros(n)
    model = DriftModel(slips_per_100m=3, slip_yaw_deg=2.0, slip_length_m=0.5)
    _, _, oyaw = apply_drift(x, y, yaw, model, np.random.default_rng(0))
    turning = np.abs(np.diff(oyaw)) > 1e-12
    assert 0 < turning.sum() <= 3 * 8  # a few bursts of ~0.5 m (0.1 m steps)
    assert DriftModel(slips_per_100m=3).is_zero  # a slip without error changes nothing


def test_typical_wheel_odometry_fills_only_the_terms_left_at_zero() -> None:
    m = DriftModel(scale_error=0.01).or_typical()
    assert m.scale_error == 0.01
    assert m.heading_walk == DriftModel.wheel_odometry().heading_walk > 0
    with pytest.raises(ConfigError, match="heading_walk"):
        DriftModel(heading_walk=-1).validate()
