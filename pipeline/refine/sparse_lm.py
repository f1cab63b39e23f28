"""Levenberg-Marquardt on a sparse Jacobian, with least_squares' Cauchy loss.

Minimises ``½ Σ ρ(r_i²)`` (``ρ(s) = C²·log(1 + s/C²)``, or ``ρ(s) = s`` without a loss)
over ``v``. Each iteration rescales the residuals and the Jacobian's rows as
``scipy.optimize.least_squares`` does for a robust loss (Triggs et al. 2000:
``J ← √(ρ' + 2ρ''r²)·J``, ``r ← ρ'/√(…)·r``), then solves the damped normal equations

    (JᵀJ + λ·D) δ = −Jᵀr,     D = the largest diagonal of JᵀJ seen so far (Marquardt's
                               scaling: the step does not depend on the variables' units)

by a sparse LU factorisation (SuperLU, single-threaded, deterministic). A pose graph's
JᵀJ has a 3 × 3 block per anchor and per constraint plus the calibration's two dense
rows and columns, so one factorisation costs about as much as one residual evaluation,
where the dense trust-region step's SVD costs O(m·n²). The damping follows Nielsen
(1999): a step that lowers the cost is taken and λ shrinks by ``max(⅓, 1 − (2ρ − 1)³)``
(``ρ`` the actual over the predicted decrease); one that does not doubles λ (then 4×, 8×…).
Stops when the cost falls by less than ``ftol`` of itself, or the step is shorter than
``xtol`` of ``‖v‖``, or after ``max_nfev`` residual evaluations.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from formats.arrays import F64

EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class Result:
    x: F64
    nfev: int


def _cost(f: F64, scale: float | None) -> float:
    if scale is None:
        return float(0.5 * np.dot(f, f))
    return float(0.5 * scale**2 * np.sum(np.log1p((f / scale) ** 2)))


def _rows_scaled(jm: object, w: F64) -> object:
    """The CSR matrix ``jm`` with row ``i`` times ``w[i]`` (``diag(w)·jm``)."""
    from scipy.sparse import csr_matrix

    m = csr_matrix(jm, copy=True)
    m.data *= np.repeat(w, np.diff(m.indptr))
    return m


def minimise(fun: Callable[[F64], F64], jac: Callable[[F64], object], v0: F64, *,
             loss_scale: float | None, max_nfev: int, ftol: float, xtol: float) -> Result:
    """``fun``'s residuals at a local minimum of the (robust) cost from ``v0``; ``jac``
    returns the residuals' Jacobian as a scipy sparse matrix; ``loss_scale`` the Cauchy
    loss's scale ``C`` (None: plain least squares)."""
    from scipy.sparse import csc_matrix, identity
    from scipy.sparse.linalg import splu

    x = np.array(v0, dtype=np.float64)
    f = fun(x)
    nfev = 1
    cost = _cost(f, loss_scale)
    lam, nu = 1e-3, 2.0
    d = np.zeros(x.shape[0])
    while nfev < max_nfev:
        jm = jac(x)
        if loss_scale is None:
            fs, js = f, jm
        else:
            z = (f / loss_scale) ** 2
            rho1 = 1.0 / (1.0 + z)
            w = np.sqrt(np.maximum(rho1 - 2.0 * rho1**2 * z, EPS))
            fs, js = f * rho1 / w, _rows_scaled(jm, w)
        # JᵀJ with every diagonal entry stored (a zero one too), so the damping adds in place
        a = csc_matrix(js.T @ js + 0.0 * identity(x.shape[0], format="csc"))  # type: ignore[attr-defined]
        a.sort_indices()
        on_diag = np.flatnonzero(a.indices == np.repeat(np.arange(a.shape[1]), np.diff(a.indptr)))
        g = np.asarray(js.T @ fs)  # type: ignore[attr-defined]
        d = np.maximum(d, a.data[on_diag])
        scaling = np.maximum(d, 1e-12 * max(float(d.max()), 1e-300))
        if float(np.abs(g).max(initial=0.0)) <= 1e-14 * max(1.0, cost):
            break
        done = False
        while nfev < max_nfev:
            damped = a.copy()
            damped.data[on_diag] += lam * scaling
            step = -splu(damped, permc_spec="COLAMD").solve(g)
            x_new = x + step
            f_new = fun(x_new)
            nfev += 1
            cost_new = _cost(f_new, loss_scale)
            predicted = -(float(g @ step) + 0.5 * float(step @ (a @ step)))
            if np.isfinite(cost_new) and cost_new < cost:
                ratio = (cost - cost_new) / predicted if predicted > 0 else 1.0
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
                nu = 2.0
                small_f = cost - cost_new < ftol * cost
                small_x = float(np.linalg.norm(step)) < xtol * (xtol + float(np.linalg.norm(x)))
                x, f, cost = x_new, f_new, cost_new
                done = small_f or small_x
                break
            lam *= nu
            nu *= 2.0
            if float(np.linalg.norm(step)) < xtol * (xtol + float(np.linalg.norm(x))):
                done = True
                break
        if done:
            break
    return Result(x, nfev)
