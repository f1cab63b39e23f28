"""The pose graph (:mod:`pipeline.refine.slam`): correlative matching, the
pose graph's analytic Jacobian, and a drifted loop refined end to end."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from formats.writers.trajectory_csv import read_trajectory
from pipeline.config import Config, PoseRefinementConfig
from pipeline.refine.correlative import LikelihoodField, Window, correlate
from pipeline.refine.graph import GraphOptions, MatchConstraints, Odometry, _Problem
from pipeline.tools.simulate import SimOptions
from pipeline.tools.trajectory_error import trajectory_error

GRAPH = dataclasses.replace(
    PoseRefinementConfig(), enabled=True, submap_travel_m=3.0, search_xy_m=0.5,
    search_yaw_deg=8.0, loop_radius_m=3.0, loop_search_xy_m=1.5, loop_search_yaw_deg=20.0)

LOOP = Path(__file__).resolve().parents[3] / "sample_logs" / "worlds" / "loop.toml"


def _room(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Arcs (echoes × 3) on the walls of an L-shaped room seen from sensors near (0, 0)."""
    t = rng.uniform(0, 1, 300)
    wall = np.where(t < 0.5, 0, 1)
    x = np.where(wall == 0, -2 + 6 * t, 4.0)
    y = np.where(wall == 0, 2.0, -1 + 6 * (t - 0.5))
    ax = np.stack([x, x + 0.01, x - 0.01], axis=1)
    ay = np.stack([y, y, y], axis=1)
    return ax, ay, np.zeros(300), np.zeros(300)


def test_correlation_finds_the_offset_and_reports_its_spread() -> None:
    rng = np.random.default_rng(0)
    rx, ry, sx, sy = _room(rng)
    qx, qy, _, _ = _room(np.random.default_rng(1))
    truth = np.array([0.3, -0.2, math.radians(3)])
    c, s = math.cos(-truth[2]), math.sin(-truth[2])
    # the query points in the frame of the true pose
    px, py = qx - truth[0], qy - truth[1]
    qx, qy = c * px - s * py, s * px + c * py
    m = correlate(rx, ry, sx, sy, qx, qy, np.zeros(3), Window(0.6, math.radians(8), 0.1,
                  math.radians(1)), res=0.05, sigma=0.1)
    assert m is not None
    assert m.pose[:2] == pytest.approx(truth[:2], abs=0.06)
    assert m.pose[2] == pytest.approx(truth[2], abs=math.radians(1))
    assert m.score > 0.8 and 0 <= m.ambiguity < 1
    assert np.all(np.linalg.eigvalsh(m.cov) > 0)


def test_a_window_that_misses_the_pose_gives_no_match() -> None:
    rx, ry, sx, sy = _room(np.random.default_rng(0))
    qx, qy, _, _ = _room(np.random.default_rng(1))
    m = correlate(rx, ry, sx, sy, qx - 1.0, qy - 1.0, np.zeros(3),
                  Window(0.3, math.radians(4), 0.1, math.radians(1)), res=0.05, sigma=0.1)
    assert m is None  # the optimum lies on the window's edge


def test_the_graphs_jacobian_is_its_residuals_derivative() -> None:
    from scipy.optimize._numdiff import approx_derivative

    rng = np.random.default_rng(0)
    x = rng.normal(size=(6, 3))
    odo = Odometry(rng.normal(size=(5, 3)), rng.uniform(0.5, 3, 5))
    u = np.triu(rng.normal(size=(2, 3, 3))) + 3 * np.eye(3)
    mc = MatchConstraints(np.array([0, 2]), np.array([3, 5]), rng.normal(size=(2, 3)), u)
    p = _Problem(x, odo, mc, GraphOptions(0.02, 0.01, True, 0.1, 0.03, 1.0))
    v = np.concatenate([x.ravel(), [0.03, 0.01]])
    numeric = approx_derivative(p.residuals, v)
    assert np.abs(p.jacobian(v).toarray() - numeric).max() < 1e-5 * np.abs(numeric).max()


@pytest.fixture(scope="module")
def loop_logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The loop corridor world (84 m, four revisits), true and with wheel odometry's drift."""
    from pipeline.tools.simulate import run_simulation

    d = tmp_path_factory.mktemp("loop")
    opts = SimOptions(sonar_model="ideal", seed=1, speed=0.5, ring_rate_hz=5.0)
    run_simulation(LOOP, d / "true.mcap", "mcap", options=opts)
    drifted = dataclasses.replace(opts, drift_scale=-0.02, drift_heading_bias_deg_per_m=-0.5,
                                  drift_heading_walk=0.01, drift_xy=0.01)
    run_simulation(LOOP, d / "walk.mcap", "mcap", options=drifted)
    return d / "true.mcap", d / "walk.mcap"


def _ate(run_dir: Path, name: str, truth: Path) -> float:
    return trajectory_error(read_trajectory(run_dir / name),
                            read_trajectory(truth)).ate_rmse_m


def test_the_graph_closes_the_loops_of_a_random_walk(loop_logs: tuple[Path, Path],
                                                     tmp_path: Path) -> None:
    from pipeline.run import run

    _, walk = loop_logs
    cfg = Config(pose_refinement=GRAPH)
    a = run(walk, tmp_path / "a", cfg)
    run(walk, tmp_path / "b", cfg)
    for name in ("trajectory.csv", "map.pgm", "trajectory.png"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    truth = walk.with_name("walk.truth.csv")
    before, after = (_ate(tmp_path / "a", "odometry.csv", truth),
                     _ate(tmp_path / "a", "trajectory.csv", truth))
    assert before > 0.5 and after < before / 3
    pr = a.metrics.pose_refinement
    assert pr is not None and pr["accepted"] is True
    assert pr["loop_closures_accepted"] >= 3 and len(pr["loop_closure_edges"]) >= 3
    assert pr["heading_bias_deg_per_m"] == pytest.approx(-0.5, abs=0.15)
    assert "graph" in pr["summary"]
    from mcap.reader import make_reader

    with (tmp_path / "a" / "map.mcap").open("rb") as f:
        topics = {c.topic: c.message_encoding for c in make_reader(f).get_summary().channels.values()}
    assert "/loop_closures" in topics and "/odometry" in topics


def test_the_graph_leaves_correct_poses_alone(loop_logs: tuple[Path, Path],
                                             tmp_path: Path) -> None:
    from pipeline.run import run

    true, _ = loop_logs
    r = run(true, tmp_path / "t", Config(pose_refinement=GRAPH))
    pr = r.metrics.pose_refinement
    assert pr is not None
    assert pr["moved_max_m"] < 0.05 or pr["accepted"] is False


def _square_graph() -> tuple[object, np.ndarray]:
    """Eight anchors 2 m apart around a 4 m square, its odometry exact, as a
    ``slam._Graph`` with no submaps."""
    from pipeline.refine.slam import _Graph
    from pipeline.se2 import between

    corners = [(0, 0, 0), (2, 0, 0), (4, 0, math.pi / 2), (4, 2, math.pi / 2),
               (4, 4, math.pi), (2, 4, math.pi), (0, 4, -math.pi / 2), (0, 2, -math.pi / 2)]
    truth = np.array(corners, float)
    odo = Odometry(between(truth[:-1], truth[1:]), np.full(7, 2.0))
    opt = GraphOptions(0.02, math.radians(0.5), True, 0.01, math.radians(2.0), 1.0, True)
    return _Graph([], odo, opt, truth.copy()), truth


def test_a_closure_the_graph_cannot_explain_is_dropped_and_the_right_ones_stay() -> None:
    from pipeline.refine.slam import CHI2_OUTLIER, _consistent

    g, truth = _square_graph()
    cov = np.diag([0.05**2, 0.05**2, math.radians(1) ** 2])
    g.add(0, 7, truth[7], cov, loop=True)  # right
    g.add(1, 6, truth[6], cov, loop=True)  # right
    wrong = truth[5] + np.array([1.5, -1.0, math.radians(25)])
    g.add(2, 5, wrong, cov, loop=True)
    keep, chi2 = _consistent(g, 7, np.ones(3, bool))
    assert keep.tolist() == [True, True, False]
    assert np.abs(g.est[:, :2] - truth[:, :2]).max() < 0.01  # solved without it
    assert chi2[2] == 0.0 and (chi2[:2] <= CHI2_OUTLIER).all()


def _room_against_room(seeds: tuple[int, int], res: float, margin: float
                       ) -> tuple[LikelihoodField, np.ndarray, np.ndarray, np.ndarray]:
    """A room's evidence field and beam coverage, and another draw of the room's echoes to
    match against it: ``(field, coverage, query x, query y)``."""
    from pipeline.refine.correlative import _coverage

    rx, ry, sx, sy = _room(np.random.default_rng(seeds[0]))
    qx, qy, _, _ = _room(np.random.default_rng(seeds[1]))
    fld = LikelihoodField.of_points(rx, ry, res=res, sigma=0.1, margin=margin)
    return fld, _coverage(fld, rx, ry, sx, sy, 0.1), qx, qy


def test_the_compiled_correlation_gives_the_numpy_versions_bits() -> None:
    from pipeline.refine.correlative import _loglik, _loglik_reference

    fld, cover, qx, qy = _room_against_room((0, 1), res=0.05, margin=1.0)
    centre = np.array([0.1, -0.05, 0.02])
    dyaw, offsets = np.linspace(-0.1, 0.1, 5), np.arange(-8, 9) * 0.05
    fast = _loglik(fld, cover, math.log(0.55), qx, qy, centre, dyaw, offsets)
    slow = _loglik_reference(fld, cover, math.log(0.55), qx, qy, centre, dyaw, offsets)
    assert fast.shape == (5, 17, 17) and np.isfinite(fast).all()
    assert np.array_equal(fast, slow)
    assert np.ptp(fast) > 1.0  # the grid sees the room, not a flat field


def test_the_compiled_correlation_keeps_its_bits_where_the_query_leaves_the_field() -> None:
    """The kernel pads the field and clamps far points: lookups near and far beyond each
    edge, and offsets that skip cells, still give the numpy version's values."""
    from pipeline.refine.correlative import _loglik, _loglik_reference

    fld, cover, qx, qy = _room_against_room((3, 4), res=0.1, margin=0.3)
    h, w = fld.values.shape
    dyaw = np.linspace(-0.2, 0.2, 3)
    for centre in (np.array([0.0, 0.0, 0.0]), np.array([w * 0.1 * 0.6, -0.4, 0.5]),
                   np.array([-50.0, 3.0, 1.0]), np.array([2.0, h * 0.1 + 0.35, -0.3])):
        for offsets in (np.arange(-4, 5) * 0.1, np.arange(-3, 4) * 0.2):
            fast = _loglik(fld, cover, math.log(0.55), qx, qy, centre, dyaw, offsets)
            slow = _loglik_reference(fld, cover, math.log(0.55), qx, qy, centre, dyaw,
                                     offsets)
            assert np.array_equal(fast, slow)
    far = _loglik(fld, cover, math.log(0.55), qx, qy, np.array([-50.0, 3.0, 1.0]), dyaw,
                  np.arange(-4, 5) * 0.1)
    assert np.allclose(far, qx.shape[0] * math.log(0.55))  # all outside: the neutral value


def test_the_compiled_coverage_gives_the_numpy_versions_cells() -> None:
    from pipeline.refine.correlative import LikelihoodField, _coverage, _coverage_reference

    rx, ry, sx, sy = _room(np.random.default_rng(2))
    for res, sigma in ((0.05, 0.1), (0.2, 0.2)):
        fld = LikelihoodField.of_points(rx, ry, res=res, sigma=sigma, margin=1.0)
        fast = _coverage(fld, rx, ry, sx, sy, sigma)
        slow = _coverage_reference(fld, rx, ry, sx, sy, sigma)
        assert fast.shape == fld.values.shape and fast.dtype == np.bool_
        assert np.array_equal(fast, slow)
        assert 0.05 < fast.mean() < 0.95  # the beams cover part of the box, not all of it
    # a field that does not reach the sensors: the rays' cells outside it are dropped
    near = LikelihoodField.of_points(rx[:5], ry[:5], res=0.05, sigma=0.1, margin=0.1)
    assert np.array_equal(_coverage(near, rx, ry, sx, sy, 0.1),
                          _coverage_reference(near, rx, ry, sx, sy, 0.1))


def _corridor(rng: np.random.Generator, half: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Arcs (echoes × 3) on the two walls of a straight corridor along x (y = ±1 m) over
    ±``half`` m, seen from sensors on its axis: nothing fixes a shift along it."""
    x = np.linspace(-half, half, 300) + rng.uniform(-0.005, 0.005, 300)
    y = np.where(rng.uniform(0, 1, 300) < 0.5, -1.0, 1.0)
    return (np.stack([x - 0.05, x, x + 0.05], axis=1), np.stack([y, y, y], axis=1), x.copy(),
            np.zeros(300))


def test_a_corridors_match_is_wide_along_it_and_sharp_across() -> None:
    rx, ry, sx, sy = _corridor(np.random.default_rng(0), 3.3)
    qx, qy, _, _ = _corridor(np.random.default_rng(1), 3.0)
    m = correlate(rx, ry, sx, sy, qx, qy - 0.1, np.zeros(3),
                  Window(0.6, math.radians(8), 0.1, math.radians(1)), res=0.05, sigma=0.1)
    assert m is not None
    assert m.pose[1] == pytest.approx(0.1, abs=0.05)  # across: the offset found
    sd_along, sd_across = math.sqrt(m.cov[0, 0]), math.sqrt(m.cov[1, 1])
    # along: every shift within ±0.3 m keeps the query on the reference's walls, as likely
    # (uniform: σ ≈ 0.17 m), not cut to the fine grid's ± two coarse steps (σ ≤ 0.12 m)
    assert sd_along > 0.15
    assert sd_across < 0.08


def test_a_submaps_own_odometry_walk_widens_its_match() -> None:
    from pipeline.refine.graph import GraphOptions
    from pipeline.refine.slam import distortion

    opt = GraphOptions(0.01, 0.01, True, 0.01, 0.03, 1.0)
    cov = distortion(np.array([0.0, 8.0, 14.0]), 1, opt)
    assert cov[2, 2] == pytest.approx(0.01**2 * 8 / 6)  # heading: σ²·L/6
    assert cov[0, 0] == pytest.approx(0.01**2 * 8 / 6 + 0.01**2 * 8 / 6 * 4.0)  # + lever L/4
    assert cov[0, 1] == 0 and cov[1, 1] == cov[0, 0]
    assert distortion(np.array([0.0, 8.0, 14.0]), 2, opt)[2, 2] == pytest.approx(0.01**2)
