"""The pose graph over submap anchors, solved by ``scipy.optimize.least_squares``.

Variables: every anchor pose ``X_i = (x, y, θ)`` and, with ``calibrate``, two odometry
calibration terms shared by the whole run — the scale error ``k`` and the heading bias
``b`` (rad per metre) of :mod:`pipeline.drift` — because wheel odometry errs
systematically (wheel radius, wheelbase) and two numbers estimated from every match
remove most of its drift. Residuals, each whitened by its square-root information:

* **odometry** between consecutive anchors: ``X_i⁻¹X_{i+1} ⊖ ô_i`` with the odometry's
  relative motion corrected by the calibration, ``ô_i = (R(−b·L_i/2)·t_i/(1+k), θ_i − b·L_i)``
  (``L_i`` the odometry path between the anchors; the chord turns by half the heading
  error accumulated along it); standard deviations ``σ_xy·√L_i + 5 mm`` and
  ``σ_θ·√L_i + 0.1° + 1 % of the turn``;
* **match** (consecutive submaps and loop closures): ``X_i⁻¹X_j ⊖ z`` whitened by the
  match's information (its posterior covariance, :mod:`pipeline.refine.correlative`);
* **priors**: anchor 0 stays where it is (σ 1 mm, 0.01°); ``k`` is pulled to
  ``scale_centre`` (the echoes' own measurement of it, else 0) and ``b`` to 0 with the
  given standard deviations.

``⊖`` subtracts poses component-wise with the angle wrapped. A robust loss (Cauchy,
scale ``robust_scale``) bounds the pull of a wrong match. The Jacobian is analytic; small
graphs take scipy's exact trust-region steps, computed from Cholesky factorisations of the
normal matrix (:mod:`pipeline.refine.trust_region`), large ones sparse
Levenberg-Marquardt steps (:data:`DENSE_MAX_VARIABLES`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from pipeline.se2 import between


@dataclass(frozen=True)
class Odometry:
    """Relative odometry motion between consecutive anchors: ``delta`` (n−1, 3) in the
    earlier anchor's frame, ``length`` (n−1,) odometry path, m."""

    delta: F64
    length: F64


@dataclass(frozen=True)
class MatchConstraints:
    """Measured relative poses ``z[m]`` of anchor ``j[m]`` in the frame of ``i[m]``, with the
    upper Cholesky factor ``u[m]`` of their information (``e·infoe = |u e|²``)."""

    i: I64
    j: I64
    z: F64  # (M, 3)
    u: F64  # (M, 3, 3)

    def __len__(self) -> int:
        return int(self.i.shape[0])

    def take(self, keep: npt.NDArray[np.bool_]) -> MatchConstraints:
        return MatchConstraints(self.i[keep], self.j[keep], self.z[keep], self.u[keep])


@dataclass(frozen=True)
class GraphOptions:
    sigma_xy: float  # m per √m
    sigma_yaw: float  # rad per √m
    calibrate: bool
    prior_scale: float  # σ of k
    prior_bias: float  # σ of b, rad/m
    robust_scale: float
    linear_start: bool = False  # solve without the robust loss first (from far-off estimates)
    scale_centre: float = 0.0  # the scale's prior mean (a measurement of it, e.g. the surfaces')


@dataclass(frozen=True)
class Solution:
    anchors: F64  # (n, 3)
    scale_error: float
    heading_bias: float  # rad per metre
    cost_initial: float
    cost_final: float
    iterations: int
    match_chi2: F64  # (M,) e·info·e of each match at the solution (no robust loss)


def sqrt_information(cov: F64) -> F64:
    """Upper factor ``u`` with ``uᵀu = cov⁻¹``."""
    info = np.linalg.inv(cov)
    info = 0.5 * (info + info.T)
    return np.asarray(np.linalg.cholesky(info).T)


def _odometry_sigmas(odo: Odometry, opt: GraphOptions) -> F64:
    root = np.sqrt(np.maximum(odo.length, 0.0))
    s_xy = opt.sigma_xy * root + 0.005
    s_yaw = opt.sigma_yaw * root + math.radians(0.1) + 0.01 * np.abs(odo.delta[:, 2])
    return np.column_stack([s_xy, s_xy, s_yaw])


class _Problem:
    def __init__(self, x0: F64, odo: Odometry, matches: MatchConstraints, opt: GraphOptions):
        self.n = x0.shape[0]
        self.first = x0[0].copy()
        self.odo = odo
        self.matches = matches
        self.opt = opt
        self.w_odo = 1.0 / _odometry_sigmas(odo, opt)
        self.n_var = 3 * self.n + (2 if opt.calibrate else 0)
        self._pattern: tuple[I64, I64, I64] | None = None
        self._places: tuple[I64, I64, int] | None = None  # the entries' rows, columns

    def unpack(self, v: F64) -> tuple[F64, float, float]:
        x = v[: 3 * self.n].reshape(self.n, 3)
        if self.opt.calibrate:
            return x, float(v[-2]), float(v[-1])
        return x, 0.0, 0.0

    def residuals(self, v: F64) -> F64:
        x, k, b = self.unpack(v)
        parts = [np.array([(x[0, 0] - self.first[0]) / 1e-3, (x[0, 1] - self.first[1]) / 1e-3,
                           float(wrap_angle(x[0, 2] - self.first[2])) / math.radians(0.01)])]
        if self.n > 1:
            rel = between(x[:-1], x[1:])
            d, length = self.odo.delta, self.odo.length
            turn = -b * length / 2
            c, s = np.cos(turn), np.sin(turn)
            px = (c * d[:, 0] - s * d[:, 1]) / (1 + k)
            py = (s * d[:, 0] + c * d[:, 1]) / (1 + k)
            e = np.column_stack([rel[:, 0] - px, rel[:, 1] - py, wrap_angle(rel[:, 2] - (d[:, 2] - b * length))])
            parts.append((e * self.w_odo).ravel())
        if len(self.matches):
            m = self.matches
            rel = between(x[m.i], x[m.j])
            e = np.column_stack([rel[:, :2] - m.z[:, :2], wrap_angle(rel[:, 2] - m.z[:, 2])])
            parts.append(np.einsum("mab,mb->ma", m.u, e).ravel())
        if self.opt.calibrate:
            parts.append(np.array([(k - self.opt.scale_centre) / self.opt.prior_scale,
                                   b / self.opt.prior_bias]))
        return np.concatenate(parts)

    def jacobian(self, v: F64) -> object:
        """The residuals' Jacobian (sparse, analytic): rows as :meth:`residuals`."""
        from scipy.sparse import coo_matrix, csr_matrix

        rows, cols, vals, n_rows = self._entries(v)
        if self._pattern is None:  # the entries' places in CSR order, found once per problem
            numbered = coo_matrix((np.arange(1.0, vals.shape[0] + 1), (rows, cols)),
                                  shape=(n_rows, self.n_var)).tocsr()
            numbered.sort_indices()
            if numbered.nnz < vals.shape[0]:  # entries sharing a place: summed each time
                return coo_matrix((vals, (rows, cols)), shape=(n_rows, self.n_var)).tocsr()
            self._pattern = (numbered.data.astype(np.int64) - 1, numbered.indices,
                             numbered.indptr)
        order, indices, indptr = self._pattern
        return csr_matrix((vals[order], indices, indptr), shape=(n_rows, self.n_var))

    def jacobian_dense(self, v: F64) -> F64:
        """:meth:`jacobian` as a dense array, filled directly (the same values: each entry
        ``0 + value`` as the sparse matrix's ``toarray`` sums it)."""
        rows, cols, vals, n_rows = self._entries(v)
        out = np.zeros((n_rows, self.n_var))
        np.add.at(out, (rows, cols), vals)
        return out

    def _entries(self, v: F64) -> tuple[I64, I64, F64, int]:
        """The Jacobian's non-zero entries: rows, columns, values and the number of rows
        (the rows and columns, which depend on the constraints alone, found once)."""
        x, k, b = self.unpack(v)
        rows: list[I64] = []
        cols: list[I64] = []
        vals: list[F64] = []
        known = self._places is not None

        def put(r0: I64, c0: I64, block: F64) -> None:
            """Blocks ``block[m]`` (3 × w) at rows ``r0[m]..+3``, columns ``c0[m]..+w``."""
            vals.append(block.ravel())
            if known:
                return
            w = block.shape[2]
            rr = r0[:, None, None] + np.arange(3)[None, :, None]
            cc = c0[:, None, None] + np.arange(w)[None, None, :]
            rows.append(np.broadcast_to(rr, block.shape).ravel())
            cols.append(np.broadcast_to(cc, block.shape).ravel())

        put(np.array([0]), np.array([0]),
            np.diag([1e3, 1e3, 1.0 / math.radians(0.01)])[None])
        r = 3

        def relative(ia: I64, ib: I64) -> tuple[F64, F64, F64]:
            a, bb = x[ia], x[ib]
            rel = between(a, bb)
            c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
            m = ia.shape[0]
            ja = np.zeros((m, 3, 3))
            ja[:, 0, 0], ja[:, 0, 1], ja[:, 0, 2] = -c, -s, rel[:, 1]
            ja[:, 1, 0], ja[:, 1, 1], ja[:, 1, 2] = s, -c, -rel[:, 0]
            ja[:, 2, 2] = -1.0
            jb = np.zeros((m, 3, 3))
            jb[:, 0, 0], jb[:, 0, 1] = c, s
            jb[:, 1, 0], jb[:, 1, 1] = -s, c
            jb[:, 2, 2] = 1.0
            return rel, ja, jb

        if self.n > 1:
            ia = np.arange(self.n - 1)
            _, ja, jb = relative(ia, ia + 1)
            w = self.w_odo[:, :, None]
            r0 = r + 3 * ia
            put(r0, 3 * ia, ja * w)
            put(r0, 3 * ia + 3, jb * w)
            if self.opt.calibrate:
                d, length = self.odo.delta, self.odo.length
                turn = -b * length / 2
                c, s = np.cos(turn), np.sin(turn)
                px = (c * d[:, 0] - s * d[:, 1]) / (1 + k)
                py = (s * d[:, 0] + c * d[:, 1]) / (1 + k)
                jc = np.zeros((self.n - 1, 3, 2))
                jc[:, 0, 0], jc[:, 1, 0] = px / (1 + k), py / (1 + k)
                jc[:, 0, 1], jc[:, 1, 1], jc[:, 2, 1] = -py * length / 2, px * length / 2, length
                put(r0, np.full(self.n - 1, self.n_var - 2), jc * w)
            r += 3 * (self.n - 1)
        if len(self.matches):
            mt = self.matches
            _, ja, jb = relative(mt.i, mt.j)
            r0 = r + 3 * np.arange(len(mt))
            put(r0, 3 * mt.i, np.einsum("mab,mbc->mac", mt.u, ja))
            put(r0, 3 * mt.j, np.einsum("mab,mbc->mac", mt.u, jb))
            r += 3 * len(mt)
        if self.opt.calibrate:
            if not known:
                rows.append(np.array([r, r + 1]))
                cols.append(np.array([self.n_var - 2, self.n_var - 1]))
            vals.append(np.array([1.0 / self.opt.prior_scale, 1.0 / self.opt.prior_bias]))
            r += 2
        if self._places is None:
            self._places = (np.concatenate(rows), np.concatenate(cols), r)
        return self._places[0], self._places[1], np.concatenate(vals), self._places[2]

    def match_chi2(self, v: F64) -> F64:
        return match_chi2(self.unpack(v)[0], self.matches)


def match_chi2(x: F64, m: MatchConstraints) -> F64:
    """Each match's ``e·info·e`` at anchors ``x`` (no robust loss)."""
    if not len(m):
        return np.zeros(0)
    rel = between(x[m.i], x[m.j])
    e = np.column_stack([rel[:, :2] - m.z[:, :2], wrap_angle(rel[:, 2] - m.z[:, 2])])
    r = np.einsum("mab,mb->ma", m.u, e)
    return np.asarray((r * r).sum(axis=1))


def robust_cost(r: F64, scale: float) -> float:
    """least_squares' Cauchy cost ``½ Σ C²·log(1 + (r/C)²)``."""
    return float(0.5 * np.sum(scale**2 * np.log1p((r / scale) ** 2)))


# Variables up to which the steps are scipy's exact trust-region steps (from a dense
# Cholesky factorisation of the n × n normal matrix per trial α, :mod:`trust_region`: ~0.3 ms
# at 300 variables; scipy's own SVD of the m × n Jacobian took ~10× that); larger graphs
# take Levenberg-Marquardt steps on the sparse Jacobian (:mod:`pipeline.refine.sparse_lm`,
# a sparse LU per step). The sparse steps on small graphs too were measured
# (docs/POSE_REFINEMENT.md, "Time"): the same solution to 1e-5 m on most solves, but a
# different local minimum on a few with wrong closures, and the Intel lab's walk row moved
# (ATE 0.241 → 0.304 m): not the default there. (scipy's iterative lsmr steps, used for
# large graphs before, stopped early: FHW's walk row solved by them reached ATE 1.73 m
# against 0.70 m exact.)
DENSE_MAX_VARIABLES = 400


def _trust_region(prob: _Problem, v0: F64, opt: GraphOptions) -> Any:
    """scipy's exact trust-region steps (:mod:`pipeline.refine.trust_region`): a
    least-squares start with ``linear_start``, then the Cauchy loss."""
    from pipeline.refine.trust_region import minimise

    if opt.linear_start:  # least squares first: a robust loss ignores what starts far off
        v0 = minimise(prob.residuals, prob.jacobian, v0, loss_scale=None, max_nfev=50,
                      xtol=1e-8, ftol=1e-8).x
    return minimise(prob.residuals, prob.jacobian, v0, loss_scale=opt.robust_scale,
                    max_nfev=200, xtol=1e-10, ftol=1e-10)


def _trust_region_scipy(prob: _Problem, v0: F64, opt: GraphOptions) -> Any:
    """:func:`_trust_region` by scipy's own ``least_squares`` (an SVD of the dense Jacobian
    per step): the reference the Cholesky steps are tested against."""
    from scipy.optimize import least_squares

    how: dict[str, object] = {"jac": prob.jacobian_dense, "tr_solver": "exact"}
    if opt.linear_start:  # least squares first: a robust loss ignores what starts far off
        v0 = least_squares(prob.residuals, v0, method="trf", x_scale="jac", max_nfev=50,
                           xtol=1e-8, ftol=1e-8, **how).x
    return least_squares(
        prob.residuals, v0, method="trf", loss="cauchy", f_scale=opt.robust_scale,
        x_scale="jac", max_nfev=200, xtol=1e-10, ftol=1e-10, **how,
    )


def solve(x0: F64, odo: Odometry, matches: MatchConstraints, opt: GraphOptions,
          method: str | None = None) -> Solution:
    """Optimise the anchors (and the calibration) from ``x0``: by ``method``
    ``"trust-region"`` (scipy's exact trust-region steps from Cholesky factorisations,
    :mod:`pipeline.refine.trust_region`), ``"scipy"`` (the same by scipy's least_squares, an
    SVD of the dense Jacobian per step: the reference) or ``"sparse"`` (Levenberg-Marquardt
    on the sparse Jacobian, :mod:`pipeline.refine.sparse_lm`); by default the first up to
    :data:`DENSE_MAX_VARIABLES` variables, the last beyond."""
    prob = _Problem(x0, odo, matches, opt)
    v0 = np.concatenate([x0.ravel(), [opt.scale_centre, 0.0] if opt.calibrate else []])
    cost0 = robust_cost(prob.residuals(v0), opt.robust_scale)
    if method is None:
        method = "trust-region" if prob.n_var <= DENSE_MAX_VARIABLES else "sparse"
    if method == "sparse":
        from pipeline.refine.sparse_lm import minimise

        if opt.linear_start:  # least squares first: a robust loss ignores what starts far off
            v0 = minimise(prob.residuals, prob.jacobian, v0, loss_scale=None, max_nfev=50,
                          xtol=1e-8, ftol=1e-8).x
        res = minimise(prob.residuals, prob.jacobian, v0, loss_scale=opt.robust_scale,
                       max_nfev=200, xtol=1e-10, ftol=1e-10)
    elif method == "scipy":
        res = _trust_region_scipy(prob, v0, opt)
    else:
        res = _trust_region(prob, v0, opt)
    x, k, b = prob.unpack(res.x)
    x = x.copy()
    x[:, 2] = wrap_angle(x[:, 2])
    return Solution(x, k, b, cost0, robust_cost(prob.residuals(res.x), opt.robust_scale),
                    int(res.nfev), prob.match_chi2(res.x))


def cost_at(x: F64, odo: Odometry, matches: MatchConstraints, opt: GraphOptions) -> float:
    """The robust cost of anchors ``x`` with a zero calibration (e.g. the raw odometry)."""
    prob = _Problem(x, odo, matches, opt)
    v = np.concatenate([x.ravel(), [0.0, 0.0] if opt.calibrate else []])
    return robust_cost(prob.residuals(v), opt.robust_scale)


def match_dof(x: F64, odo: Odometry, matches: MatchConstraints, opt: GraphOptions,
              scale: float, bias: float) -> float:
    """The degrees of freedom the matches add to the graph at ``x`` (calibration ``scale``,
    ``bias``): the trace of their share of the information, ``tr((JᵀJ)⁻¹·J_mᵀJ_m)``
    (whitened Jacobian ``J``, its match rows ``J_m``) — 3 per match that nothing else
    constrains, less for one the odometry already pins or that repeats another."""
    if not len(matches):
        return 0.0
    prob = _Problem(x, odo, matches, opt)
    v = np.concatenate([x.ravel(), [scale, bias] if opt.calibrate else []])
    jac = prob.jacobian_dense(v)
    first = 3 + 3 * (prob.n - 1)
    jm = jac[first:first + 3 * len(matches)]
    info = jac.T @ jac
    return float(np.trace(np.linalg.solve(info, jm.T @ jm)))
