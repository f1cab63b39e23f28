"""scipy's trust-region least squares with its steps from Cholesky factorisations.

The iteration is ``scipy.optimize.least_squares(method="trf", tr_solver="exact",
x_scale="jac")`` without bounds, step for step: the residuals and Jacobian rescaled for a
Cauchy loss (Triggs et al. 2000, as scipy does), the variables scaled by the Jacobian's
column norms (never shrinking), the radius Δ grown ×2 when a step on the boundary does
better than ¾ of its prediction and cut to ¼ of the step below ¼, and the same stopping
tests (``ftol`` on the cost, ``xtol`` on the step, ``gtol`` on the gradient). Only the
linear algebra of each step differs. The step solves Moré's (1977) subproblem

    min ‖J_h·p + f‖  subject to  ‖p‖ ≤ Δ      (J_h: the scaled Jacobian)

— the Gauss-Newton step if it lies inside, else ``(J_hᵀJ_h + α·I)·p = −J_hᵀf`` with α
found by Moré's safeguarded Newton iteration on ``‖p(α)‖ = Δ`` to 1 %, from the previous
step's α. scipy evaluates ``‖p(α)‖`` and its derivative ``−pᵀ(J_hᵀJ_h + α·I)⁻¹p / ‖p‖``
from one SVD of the dense Jacobian per step, O(m·n²); here each α is one Cholesky
factorisation of the n × n normal matrix, formed from the sparse Jacobian (a pose graph's
is 3 × 3 blocks): n³/3 per α, ~4 per step, about a tenth of the SVD at n ≈ 300. The
normal matrix squares the Jacobian's condition number, so the iterates agree with
scipy's to rounding times that (tests: to 1e-9 on pose graphs), not bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dpotrf, dpotrs
from scipy.sparse import csr_matrix

from formats.arrays import F64

EPS = float(np.finfo(float).eps)
RTOL = 0.01  # α's iteration stops when ‖p‖ is within this share of Δ (scipy's)
MAX_ALPHA_ITERATIONS = 10


@dataclass(frozen=True)
class Result:
    x: F64
    nfev: int
    status: int  # scipy's: 1 gtol, 2 ftol, 3 xtol, 4 both, 0 max_nfev


def _factor(a: F64, alpha: float) -> F64 | None:
    """Upper Cholesky factor of ``a + α·I``, or None when not positive definite."""
    m = a.copy()
    m.flat[:: m.shape[0] + 1] += alpha  # the diagonal
    c, info = dpotrf(m, lower=0, clean=0, overwrite_a=1)
    return None if info != 0 else np.asarray(c)


def _solve(c: F64, b: F64) -> F64:
    x, info = dpotrs(c, b, lower=0)
    assert info == 0
    return np.asarray(x)


@dataclass(frozen=True)
class _GaussNewton:
    """A step's Gauss-Newton solution of the scaled normal equations ``a·p = −g``, whatever
    the radius (found once per Jacobian, as scipy's SVD): None where ``a`` is singular."""

    p: F64 | None
    p_norm: float
    slope: float  # d‖p(α)‖/dα at α = 0: −pᵀa⁻¹p / ‖p‖

    @staticmethod
    def of(a: F64, g: F64, m_rows: int) -> _GaussNewton:
        fac = _factor(a, 0.0) if m_rows >= a.shape[0] else None
        # full rank as scipy's SVD tells it (s_min > ε·m·s_max), from the factor's pivots
        if fac is None or not (float(np.abs(np.diag(fac)).min()) ** 2
                               > (EPS * m_rows) ** 2 * float(np.diag(a).max())):
            return _GaussNewton(None, 0.0, 0.0)
        p = -_solve(fac, g)
        p_norm = float(np.linalg.norm(p))
        return _GaussNewton(p, p_norm, -float(p @ _solve(fac, p)) / p_norm if p_norm else 0.0)


def _step(a: F64, g: F64, gn: _GaussNewton, delta: float, alpha: float) -> tuple[F64, float]:
    """Moré's trust-region step for the normal matrix ``a`` and gradient ``g`` (scaled),
    radius ``delta``, from ``alpha``: the step and its α (0 for Gauss-Newton)."""
    alpha_upper = float(np.linalg.norm(g)) / delta
    alpha_lower = 0.0
    if gn.p is not None:
        if gn.p_norm <= delta:
            return gn.p, 0.0
        alpha_lower = -(gn.p_norm - delta) / gn.slope
    elif alpha == 0:
        alpha = max(0.001 * alpha_upper, (alpha_lower * alpha_upper) ** 0.5)
    for _ in range(MAX_ALPHA_ITERATIONS):
        if alpha < alpha_lower or alpha > alpha_upper:
            alpha = max(0.001 * alpha_upper, (alpha_lower * alpha_upper) ** 0.5)
        fac = _factor(a, alpha)
        assert fac is not None  # a is positive semi-definite and α > 0
        p = _solve(fac, g)
        p_norm = float(np.linalg.norm(p))
        phi = p_norm - delta
        phi_prime = -float(p @ _solve(fac, p)) / p_norm
        if phi < 0:
            alpha_upper = alpha
        ratio = phi / phi_prime
        alpha_lower = max(alpha_lower, alpha - ratio)
        alpha -= (phi + delta) * ratio / delta
        if abs(phi) < RTOL * delta:
            break
    fac = _factor(a, alpha)
    assert fac is not None
    p = -_solve(fac, g)
    return p * (delta / float(np.linalg.norm(p))), alpha


def minimise(fun: Callable[[F64], F64], jac: Callable[[F64], object], v0: F64, *,
             loss_scale: float | None, max_nfev: int, ftol: float, xtol: float,
             gtol: float = 1e-8) -> Result:
    """``fun``'s residuals at a local minimum of ``½ Σ ρ(r²)`` from ``v0`` (``ρ`` Cauchy of
    scale ``loss_scale``, or None: ``ρ(s) = s``), as ``least_squares(method="trf",
    tr_solver="exact", x_scale="jac", loss="cauchy", f_scale=loss_scale, max_nfev, ftol,
    xtol, gtol)`` reaches it; ``jac`` returns the residuals' Jacobian as a scipy sparse
    matrix."""
    x = np.array(v0, dtype=np.float64)
    f = fun(x)
    nfev = 1
    b, g, cost = _normal_equations(jac(x), f, loss_scale)
    scale_inv = np.sqrt(np.diag(b)).copy()
    scale_inv[scale_inv == 0] = 1.0
    delta = float(np.linalg.norm(x * scale_inv)) or 1.0
    alpha = 0.0
    status = 0
    m_rows = f.shape[0]
    while True:
        if float(np.abs(g).max(initial=0.0)) < gtol:
            status = 1
        if status or nfev == max_nfev:
            break
        d = 1.0 / scale_inv
        g_h = d * g
        a = d[:, None] * b * d[None, :]
        gn = _GaussNewton.of(a, g_h, m_rows)
        reduction = -1.0
        while reduction <= 0 and nfev < max_nfev:
            step_h, alpha = _step(a, g_h, gn, delta, alpha)
            predicted = -(0.5 * float(step_h @ (a @ step_h)) + float(g_h @ step_h))
            step = d * step_h
            x_new = x + step
            f_new = fun(x_new)
            nfev += 1
            step_h_norm = float(np.linalg.norm(step_h))
            if not np.all(np.isfinite(f_new)):
                delta = 0.25 * step_h_norm
                continue
            cost_new = _cost(f_new, loss_scale)
            reduction = cost - cost_new
            ratio = (reduction / predicted if predicted > 0
                     else 1.0 if predicted == reduction == 0 else 0.0)
            delta_new = delta
            if ratio < 0.25:
                delta_new = 0.25 * step_h_norm
            elif ratio > 0.75 and step_h_norm > 0.95 * delta:
                delta_new = 2.0 * delta
            small_f = reduction < ftol * cost and ratio > 0.25
            small_x = (float(np.linalg.norm(step))
                       < xtol * (xtol + float(np.linalg.norm(x))))
            status = 4 if small_f and small_x else 2 if small_f else 3 if small_x else 0
            if status:
                break
            alpha *= delta / delta_new
            delta = delta_new
        if reduction > 0:
            x, cost = x_new, cost_new
            b, g, _ = _normal_equations(jac(x), f_new, loss_scale)
            scale_inv = np.maximum(np.sqrt(np.diag(b)), scale_inv)
    return Result(x, nfev, status)


def _cost(f: F64, scale: float | None) -> float:
    if scale is None:
        return float(0.5 * np.dot(f, f))
    return float(0.5 * scale**2 * np.sum(np.log1p((f / scale) ** 2)))


def _normal_equations(jm: object, f: F64, scale: float | None) -> tuple[F64, F64, float]:
    """``(JᵀJ, Jᵀf)`` of the Jacobian ``jm`` and residuals ``f`` rescaled for the Cauchy
    loss (rows × ``√(ρ' + 2ρ''r²)``, residuals × ``ρ'/√(…)``), and the cost."""
    from pipeline.refine.kernels import normal_equations

    csr = csr_matrix(jm)
    if scale is None:
        w, fs, cost = np.ones(f.shape[0]), f, float(0.5 * np.dot(f, f))
    else:
        z = (f / scale) ** 2
        rho1 = 1.0 / (1.0 + z)
        w = rho1 - 2.0 * f**2 / (scale**2 * (1.0 + z) ** 2)
        w[w < EPS] = EPS
        w = np.sqrt(w)
        fs, cost = f * rho1 / w, float(0.5 * scale**2 * np.sum(np.log1p(z)))
    a, g = normal_equations(csr.indptr.astype(np.int64), csr.indices.astype(np.int64),
                            np.asarray(csr.data, np.float64), w, np.asarray(fs, np.float64),
                            csr.shape[1])
    return np.asarray(a), np.asarray(g), cost
