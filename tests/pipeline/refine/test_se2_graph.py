"""SE(2) helpers and the pose graph (pipeline.se2, pipeline.refine.graph)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.refine.graph import GraphOptions, MatchConstraints, Odometry, solve, sqrt_information
from pipeline.se2 import between, compose, inverse, transform_points


def test_compose_inverse_between_agree() -> None:
    a = np.array([1.0, 2.0, 0.5])
    b = np.array([-0.3, 0.7, 2.9])
    ab = compose(a, b)
    np.testing.assert_allclose(between(a, ab), b, atol=1e-12)
    assert -math.pi <= ab[2] < math.pi
    np.testing.assert_allclose(compose(a, inverse(a)), [0.0, 0.0, 0.0], atol=1e-12)
    x, y = transform_points(np.array([1.0, 0.0, math.pi / 2]), np.array([1.0]), np.array([0.0]))
    assert x[0] == pytest.approx(1.0) and y[0] == pytest.approx(1.0)


def square(n_side: int = 4) -> np.ndarray:
    """Anchors around a 4 m square, 1 m apart, heading along the path."""
    pts = []
    for side in range(4):
        yaw = side * math.pi / 2
        cx, cy = [(0, 0), (4, 0), (4, 4), (0, 4)][side]
        for k in range(n_side):
            pts.append((cx + k * math.cos(yaw), cy + k * math.sin(yaw), yaw))
    return np.array(pts)


def opts(calibrate: bool) -> GraphOptions:
    return GraphOptions(0.02, math.radians(0.5), calibrate, 0.1, math.radians(2.0), 3.0)


def biased_square() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The true square, and odometry 5 % long turning 1 degree per metre too far (the
    graph's own model): (truth, odometry steps, their travelled lengths, dead reckoning)."""
    truth = square()
    rel = between(truth[:-1], truth[1:])
    length = np.hypot(rel[:, 0], rel[:, 1])
    b = math.radians(1.0)
    c, s = np.cos(b * length / 2), np.sin(b * length / 2)
    odo = np.column_stack([1.05 * (c * rel[:, 0] - s * rel[:, 1]),
                           1.05 * (s * rel[:, 0] + c * rel[:, 1]), rel[:, 2] + b * length])
    x0 = [truth[0]]
    for d in odo:
        x0.append(compose(x0[-1], d))
    return truth, odo, 1.05 * length, np.array(x0)


def test_loop_closure_and_calibration_recover_a_biased_square() -> None:
    truth, odo, travelled, x0 = biased_square()
    # Exact matches between every consecutive pair and one loop closure (last -> first).
    i = np.r_[np.arange(15), 15]
    j = np.r_[np.arange(1, 16), 0]
    z = between(truth[i], truth[j])
    u = np.repeat(sqrt_information(np.diag([0.05**2, 0.05**2, math.radians(2) ** 2]))[None], 16, 0)
    sol = solve(x0, Odometry(odo, travelled), MatchConstraints(i, j, z, u), opts(True))
    assert sol.cost_final < sol.cost_initial
    np.testing.assert_allclose(sol.anchors[:, :2], truth[:, :2], atol=0.02)
    assert sol.scale_error == pytest.approx(0.05, abs=0.01)
    assert math.degrees(sol.heading_bias) == pytest.approx(1.0 * 1.05, abs=0.15)
    assert sol.match_chi2.shape == (16,) and sol.match_chi2.max() < 1.0


def test_a_wrong_loop_closure_has_a_large_chi2() -> None:
    truth = square()
    rel = between(truth[:-1], truth[1:])
    odo = Odometry(rel, np.hypot(rel[:, 0], rel[:, 1]))
    z = np.array([[2.0, 1.0, 0.5]])  # nothing like the truth's last -> first
    u = sqrt_information(np.diag([0.05**2, 0.05**2, math.radians(2) ** 2]))[None]
    sol = solve(truth.copy(), odo, MatchConstraints(np.array([15]), np.array([0]), z, u),
                opts(False))
    assert sol.match_chi2[0] > 16.0  # what drops it (slam.CHI2_OUTLIER) before the last solve
    # the Cauchy loss bounds its pull: a closure 2.2 m off moves no anchor by as much
    assert np.abs(sol.anchors[:, :2] - truth[:, :2]).max() < 1.5


def test_the_dense_jacobian_is_the_sparse_ones_entries() -> None:
    from pipeline.refine.graph import _Problem

    truth = square()
    rel = between(truth[:-1], truth[1:])
    odo = Odometry(rel * 1.03, np.hypot(rel[:, 0], rel[:, 1]))
    i, j = np.array([0, 3, 15]), np.array([1, 12, 0])
    u = np.repeat(sqrt_information(np.diag([0.05**2, 0.03**2, 0.02**2]))[None], 3, 0)
    mc = MatchConstraints(i, j, between(truth[i], truth[j]) + 0.01, u)
    prob = _Problem(truth, odo, mc, opts(True))
    v = np.concatenate([truth.ravel() + 0.01 * np.sin(np.arange(48)), [0.02, -0.01]])
    dense = prob.jacobian_dense(v)
    sparse = prob.jacobian(v).toarray()  # type: ignore[attr-defined]
    assert dense.shape == (3 + 45 + 9 + 2, 50)
    assert np.array_equal(dense, sparse) and not np.signbit(dense[dense == 0]).any()
    # the finite differences of the residuals agree with the analytic entries
    h = 1e-7
    fd = np.column_stack([(prob.residuals(v + h * e) - prob.residuals(v - h * e)) / (2 * h)
                          for e in np.eye(50)])
    np.testing.assert_allclose(dense, fd, atol=1e-4 * np.abs(dense).max())


def test_the_sparse_steps_reach_the_trust_regions_solution() -> None:
    truth, odo, travelled, x0 = biased_square()
    i, j = np.r_[np.arange(15), 15, 2], np.r_[np.arange(1, 16), 0, 9]
    z = between(truth[i], truth[j])
    z[-1] += [1.0, -0.8, 0.3]  # one wrong closure: the Cauchy loss bounds it
    u = np.repeat(sqrt_information(np.diag([0.05**2, 0.05**2, math.radians(2) ** 2]))[None], 17, 0)
    args = (x0, Odometry(odo, travelled), MatchConstraints(i, j, z, u))
    opt = GraphOptions(0.02, math.radians(0.5), True, 0.1, math.radians(2.0), 1.0, True)
    sparse = solve(*args, opt, method="sparse")
    exact = solve(*args, opt, method="trust-region")
    assert sparse.cost_final == pytest.approx(exact.cost_final, rel=1e-6)
    np.testing.assert_allclose(sparse.anchors, exact.anchors, atol=1e-5)
    assert sparse.scale_error == pytest.approx(exact.scale_error, abs=1e-6)
    assert sparse.heading_bias == pytest.approx(exact.heading_bias, abs=1e-7)
    assert sparse.match_chi2[-1] > 16.0 and sparse.match_chi2[:-1].max() < 16.0
    again = solve(*args, opt, method="sparse")
    assert np.array_equal(again.anchors, sparse.anchors)  # deterministic to the bit


def test_the_matches_degrees_of_freedom_count_what_they_add() -> None:
    from pipeline.refine.graph import match_dof

    truth, odo, travelled, x0 = biased_square()
    one = sqrt_information(np.diag([0.01**2, 0.01**2, math.radians(0.1) ** 2]))[None]
    loop = MatchConstraints(np.array([0]), np.array([15]), between(truth[[0]], truth[[15]]), one)
    opt = opts(False)
    # one precise closure over a long loop: nearly all its three coordinates are new
    assert 2.5 < match_dof(x0, Odometry(odo, travelled), loop, opt, 0.0, 0.0) <= 3.0
    # the same closure twice: together still at most three
    twice = MatchConstraints(np.array([0, 0]), np.array([15, 15]), np.repeat(loop.z, 2, 0),
                             np.repeat(one, 2, 0))
    assert match_dof(x0, Odometry(odo, travelled), twice, opt, 0.0, 0.0) <= 3.0
    # a vague match between neighbours adds almost nothing to their odometry
    vague = MatchConstraints(np.array([3]), np.array([4]), between(truth[[3]], truth[[4]]),
                             sqrt_information(np.diag([5.0**2, 5.0**2, 1.0]))[None])
    assert match_dof(x0, Odometry(odo, travelled), vague, opt, 0.0, 0.0) < 0.05
    assert match_dof(x0, Odometry(odo, travelled), loop.take(np.array([False])), opt,
                     0.0, 0.0) == 0.0


def test_the_cholesky_steps_are_scipys_trust_region_steps() -> None:
    """pipeline.refine.trust_region takes scipy's exact trust-region steps (an SVD per step
    there, Cholesky factorisations here): the same iterations, the same solution to 1e-9,
    from the least-squares start and under the Cauchy loss, with a wrong closure."""
    truth, odo, travelled, x0 = biased_square()
    i, j = np.r_[np.arange(15), 15, 2], np.r_[np.arange(1, 16), 0, 9]
    z = between(truth[i], truth[j])
    z[-1] += [1.0, -0.8, 0.3]
    u = np.repeat(sqrt_information(np.diag([0.05**2, 0.05**2, math.radians(2) ** 2]))[None], 17, 0)
    args = (x0, Odometry(odo, travelled), MatchConstraints(i, j, z, u))
    for linear_start in (False, True):
        opt = GraphOptions(0.02, math.radians(0.5), True, 0.1, math.radians(2.0), 1.0,
                           linear_start)
        ours = solve(*args, opt)
        scipy = solve(*args, opt, method="scipy")
        assert ours.iterations == scipy.iterations > 5
        np.testing.assert_allclose(ours.anchors, scipy.anchors, rtol=0, atol=1e-9)
        assert ours.scale_error == pytest.approx(scipy.scale_error, abs=1e-9)
        assert ours.heading_bias == pytest.approx(scipy.heading_bias, abs=1e-9)
        assert ours.cost_final == pytest.approx(scipy.cost_final, rel=1e-9)
        assert ours.match_chi2[-1] > 16.0  # the wrong closure stands out in both


def test_the_trust_region_stops_as_scipy_does() -> None:
    """The stopping tests of scipy's trf, each status and evaluation count as scipy reports
    them (a Rosenbrock valley with a residual left at its minimum): ftol (2), both (4),
    xtol (3), max_nfev (0), with and without the Cauchy loss; gtol (1) at a minimum."""
    from scipy.optimize import least_squares
    from scipy.sparse import csr_matrix

    from pipeline.refine.trust_region import minimise

    def fun(v: np.ndarray) -> np.ndarray:
        return np.array([10 * (v[1] - v[0] ** 2), 1 - v[0], 0.3 * (v[0] + v[1] - 1)])

    def jac(v: np.ndarray) -> np.ndarray:
        return np.array([[-20 * v[0], 10.0], [-1.0, 0.0], [0.3, 0.3]])

    start = np.array([-1.2, 1.0])
    for status, kw in ((2, {"ftol": 1e-6, "xtol": 1e-15, "max_nfev": 100}),
                       (4, {"ftol": 1e-2, "xtol": 1e-2, "max_nfev": 100}),
                       (3, {"ftol": 1e-15, "xtol": 1e-6, "max_nfev": 100}),
                       (0, {"ftol": 1e-15, "xtol": 1e-15, "max_nfev": 5})):
        for loss in (None, 1.0):
            ours = minimise(fun, lambda v: csr_matrix(jac(v)), start, loss_scale=loss,
                            gtol=1e-12, **kw)
            ref = least_squares(fun, start, jac=jac, method="trf", tr_solver="exact",
                                x_scale="jac", loss="linear" if loss is None else "cauchy",
                                f_scale=loss or 1.0, gtol=1e-12, **kw)
            assert ours.status == ref.status == status
            assert ours.nfev == ref.nfev
            np.testing.assert_allclose(ours.x, ref.x, rtol=0, atol=1e-9)
    exact = minimise(lambda v: fun(v)[:2], lambda v: csr_matrix(jac(v)[:2]), np.ones(2),
                     loss_scale=None, ftol=1e-8, xtol=1e-8, max_nfev=10)
    assert (exact.status, exact.nfev) == (1, 1)  # a zero gradient at the start: gtol
