"""Local corrections after the calibration (``[pose_refinement] local_corrections``): a
rigid correction at knots along the run, blended between them, found by a robust linear
least squares over the surface patches every visit of a place shares.

A calibration removes what the whole run shares (scale, heading bias); odometry noise per
step is a random walk that it cannot remove. Where the robot sees a wall again, the
echoes of every visit must agree on the wall's offset (:mod:`pipeline.refine.surfaces`:
``n·s − r cos γ = c`` for a plane of normal ``n``), so the visits' pose errors show as
disagreements of that offset, and they are linear in small pose corrections:

Design notes and the measurements behind them: docs/research/pose_refinement.md, "How it works", item 3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from pipeline.refine import surfaces
from pipeline.refine.calibration import consistency_change, gate_digits
from pipeline.refine.echoes import Echoes
from pipeline.refine.scores import MAX_ECHOES_CONSISTENCY, Consistency, thin
from pipeline.refine.submaps import path_length
from pipeline.refine.surfaces import CAUCHY, MAD_SIGMA, Cones
from pipeline.se2 import transform_points

HeldOut = Literal["off", "measure", "gate"]  # the held-out test (module docstring)

IRLS_STEPS = 6
WALK_EM_STEPS = 3  # the random walk's σ estimated in this many steps per reweighting
WALK_FLOOR = 0.01  # ... at least this fraction of the configured σ


@dataclass(frozen=True)
class Corrected:
    """The corrected poses (the odometry's stamps) and what the adjustment found."""

    x: F64
    y: F64
    yaw: F64
    metrics: dict[str, Any]


def correct_stretches(t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, *,
                      stretch_m: float, sigma_xy: float, sigma_yaw: float, iterations: int,
                      min_gain: float, min_consistency_gain: float = 0.01,
                      strong_gain: float = math.inf, held_out: HeldOut = "off",
                      noise_estimated: bool = True, res: float = 0.05,
                      sigma: float = 0.1) -> Corrected:
    """The poses ``(x, y, yaw)`` at ``t_ns`` with the stretches' corrections (module
    docstring), or as given when the gates keep them out; ``echoes``: the echoes with the
    odometry they were taken at (their poses follow the track); ``min_consistency_gain``,
    ``res``, ``sigma``: the second gate's (echo consistency at cells ``2 res``, blur
    ``sigma``, as the calibration's); ``held_out``: the second gate judged on echoes the
    corrections were not fitted to (module docstring, *held out*)."""
    given = (x, y, yaw)
    solve = _Solver(t_ns, stretch_m, sigma_xy, sigma_yaw, iterations, noise_estimated)
    # only the echoes each score reads (thinned evenly, as the scores thin them) follow the
    # corrected track: a long log's hundreds of thousands are not interpolated each solve
    matched = echoes.take(thin(len(echoes), surfaces.MAX_ECHOES))
    scored = echoes.take(thin(len(echoes), MAX_ECHOES_CONSISTENCY))
    fitted = solve(x, y, yaw, matched, min_gain)
    metrics = fitted.metrics
    if metrics.get("gain_per_parameter", math.inf) < min_gain:
        metrics["note"] = (f"not applied: the patches' loss falls by "
                           f"{metrics['gain_per_parameter']:.2f} per parameter (< {min_gain:g})")
    if not metrics["iterations"]:
        metrics["applied"] = False
        return Corrected(*given, metrics)
    gain = track_consistency_gain(t_ns, given, fitted.poses, scored, res, sigma)
    metrics["consistency_gain"] = gain
    if held_out == "measure":
        metrics["held_out_consistency_gain"] = _held_out_gain(solve, given, echoes, res, sigma)
    needed = consistency_needed(metrics["gain_per_parameter"], min_consistency_gain, strong_gain)
    if gain < needed:
        d = gate_digits(gain, needed)
        metrics["note"] = (f"not applied: the echoes would be {consistency_change(gain, d)} "
                           f"(< {needed:.{d}%})")
        metrics["applied"] = False
        return Corrected(*given, metrics)
    if held_out == "gate":
        held = metrics["held_out_consistency_gain"] = _held_out_gain(solve, given, echoes, res,
                                                                     sigma)
        if held < 0.0:
            metrics["note"] = ("not applied: fitted to half the echoes, they leave the other "
                               f"half {consistency_change(held, 2)}")
            metrics["applied"] = False
            return Corrected(*given, metrics)
    metrics["applied"] = True
    return Corrected(*fitted.poses, metrics)


def _held_out_gain(solve: _Solver, given: tuple[F64, F64, F64], echoes: Echoes, res: float,
                   sigma: float) -> float:
    """The consistency gain of the odd echoes under corrections fitted to the even ones
    (0 where those find none to fit)."""
    even, odd = (echoes.take(np.arange(start, len(echoes), 2)) for start in (0, 1))
    apart = solve(*given, even.take(thin(len(even), surfaces.MAX_ECHOES)))
    if not apart.metrics["iterations"]:
        return 0.0
    scored = odd.take(thin(len(odd), MAX_ECHOES_CONSISTENCY))
    return track_consistency_gain(solve.t_ns, given, apart.poses, scored, res, sigma)


@dataclass(frozen=True)
class _Fitted:
    """The poses after a run of solves, and what they did (the first solve's gate numbers,
    absent where none ran: one stretch, no echo, no patch)."""

    poses: tuple[F64, F64, F64]
    metrics: dict[str, Any]


@dataclass(frozen=True)
class _Solver:
    """``iterations`` solves (each after associating again) of a track's corrections at
    its knots from a set of echoes."""

    t_ns: I64
    stretch_m: float
    sigma_xy: float
    sigma_yaw: float
    iterations: int
    noise_estimated: bool = True

    def __call__(self, x: F64, y: F64, yaw: F64, echoes: Echoes,
                 min_gain: float = -math.inf) -> _Fitted:
        """The solves from ``(x, y, yaw)``; none applied when the first lowers the patches'
        loss by less than ``min_gain`` per parameter."""
        t_ns = self.t_ns
        metrics: dict[str, Any] = {"stretches": 0, "iterations": 0}
        cones = Cones(echoes, window_m=0.0)  # the echoes' arcs, the same for every solve
        for it in range(self.iterations):
            travel = path_length(x, y)
            knots = Knots.along(travel, x, y, self.stretch_m)
            if knots is None or len(echoes) == 0:
                break
            solved = _solve(t_ns, cones, echoes.on_track(t_ns, x, y, yaw).odo, travel, knots,
                            RandomWalk(self.sigma_xy, self.sigma_yaw), self.noise_estimated)
            if solved is None:
                break
            corr, loss_before, loss_after, dof, walk = solved
            if it == 0:  # the gate's solve: the optimiser's cost without and with the corrections
                gain_per_parameter = (loss_before - loss_after) / max(dof, 1)
                metrics.update(stretches=knots.stretches, loss_before=loss_before,
                               loss_after=loss_after, gain_per_parameter=gain_per_parameter)
                if self.noise_estimated:
                    metrics.update(noise_xy_m_per_sqrt_m=walk.xy,
                                   noise_yaw_deg_per_sqrt_m=math.degrees(walk.yaw))
                if gain_per_parameter < min_gain:
                    break
            x, y, yaw = knots.apply(x, y, yaw, travel, corr)
            metrics["iterations"] = it + 1
        return _Fitted((x, y, yaw), metrics)


@dataclass(frozen=True)
class Knots:
    """The corrections' knots: the first pose (held at zero: the odometry's error is nil
    where it starts), then every ``stretch_m`` or a little less of travel to the last pose;
    each knot's pivot is the track's position there. A pose between two knots is moved by
    both knots' rigid corrections (a rotation about the knot's pivot, then a translation),
    blended by its travel between them: a correction that grows along the run as the
    odometry's error does, instead of one jump per stretch."""

    at: F64  # (n + 1,) each knot's travel, m
    pivot: F64  # (n + 1, 2) the track's position there, m

    @staticmethod
    def along(travel: F64, x: F64, y: F64, stretch_m: float) -> Knots | None:
        """The knots of a track whose poses have ``travel``; None for a run of at most one
        stretch (nothing to correct against)."""
        n = math.ceil(travel[-1] / stretch_m - 1e-9)
        if n < 2:
            return None
        at = np.linspace(0.0, float(travel[-1]), n + 1)
        return Knots(at, np.column_stack([np.interp(at, travel, x), np.interp(at, travel, y)]))

    @property
    def stretches(self) -> int:
        return int(self.at.shape[0]) - 1

    @property
    def stretch_m(self) -> float:
        return float(self.at[-1]) / self.stretches

    def between(self, travel: F64) -> tuple[I64, F64]:
        """The knot before each ``travel`` and the weight of the one after it."""
        k = np.clip(np.searchsorted(self.at, travel, side="right") - 1, 0, self.stretches - 1)
        return k, np.clip((travel - self.at[k]) / (self.at[k + 1] - self.at[k]), 0.0, 1.0)

    def carried(self) -> F64:
        """(3n, 3n): the random walk's steps as rows over the free knots' corrections
        ``(t_x, t_y, θ)``: knot ``j + 1``'s minus knot ``j``'s carried on rigidly to knot
        ``j + 1``'s pivot (``t + θ J Δ``; knot 0 is zero): a heading error turns the rest of
        the run about where it happened, and costs only its own step."""
        n = self.stretches
        steps = np.eye(3 * n)
        for j in range(1, n):
            ddx, ddy = self.pivot[j + 1] - self.pivot[j]
            steps[3 * j:3 * j + 3, 3 * j - 3:3 * j] = -np.array(
                [[1.0, 0.0, -ddy], [0.0, 1.0, ddx], [0.0, 0.0, 1.0]])
        return steps

    def apply(self, x: F64, y: F64, yaw: F64, travel: F64, corr: F64
              ) -> tuple[F64, F64, F64]:
        """The poses moved by the knots' corrections ``corr`` (n + 1, 3), as above."""
        k, w = self.between(travel)

        def moved(j: I64) -> tuple[F64, F64]:
            c, s = np.cos(corr[j, 2]), np.sin(corr[j, 2])
            mx, my = self.pivot[j, 0], self.pivot[j, 1]
            return (mx + c * (x - mx) - s * (y - my) + corr[j, 0],
                    my + s * (x - mx) + c * (y - my) + corr[j, 1])

        (ax, ay), (bx, by) = moved(k), moved(k + 1)
        turn = (1 - w) * corr[k, 2] + w * corr[k + 1, 2]
        return (1 - w) * ax + w * bx, (1 - w) * ay + w * by, wrap_angle(yaw + turn)


@dataclass(frozen=True)
class RandomWalk:
    """The odometry's random walk: σ per √m of travel, in position (m) and heading (rad)."""

    xy: float
    yaw: float

    def step_sd(self, knots: Knots) -> F64:
        """(3n,): each step's σ between consecutive knots."""
        return np.tile([self.xy, self.xy, self.yaw], knots.stretches) * math.sqrt(knots.stretch_m)


def consistency_needed(gain_per_parameter: float, min_consistency_gain: float,
                       strong_gain: float) -> float:
    """The consistency gain the second gate asks of corrections whose first solve lowered
    the patches' loss by ``gain_per_parameter``: none where that reaches ``strong_gain``
    (module docstring, strong evidence), else ``min_consistency_gain``."""
    return 0.0 if gain_per_parameter >= strong_gain else min_consistency_gain


def track_consistency_gain(t_ns: I64, given: tuple[F64, F64, F64],
                            corrected: tuple[F64, F64, F64], echoes: Echoes, res: float,
                            sigma: float) -> float:
    """How much more consistent (fraction) ``echoes`` are on the ``corrected`` track than on
    the ``given`` one."""
    return (_consistency(t_ns, *corrected, echoes, res, sigma)
            / _consistency(t_ns, *given, echoes, res, sigma) - 1.0)


def _consistency(t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes, res: float,
                 sigma: float) -> float:
    """The echoes' consistency (:class:`pipeline.refine.scores.Consistency`) with
    their poses on the track ``(x, y, yaw)``."""
    return Consistency(t_ns, x, y, yaw, echoes.on_track(t_ns, x, y, yaw), res=2 * res,
                       sigma=sigma)(0.0, 0.0)


def _solve(t_ns: I64, cones: Cones, poses: F64, travel: F64, knots: Knots, walk: RandomWalk,
           noise_estimated: bool) -> tuple[F64, float, float, int, RandomWalk] | None:
    """(corrections at the knots (n + 1, 3), the patches' robust loss without and with them,
    the parameters, the random walk's σ used) of one linearised solve of the echoes of
    ``cones`` at ``poses`` (the track's stamped ``t_ns``, with ``travel``). The patches'
    offsets are eliminated (each is the weighted mean of its rows), which leaves a dense
    system of 3 unknowns per knot. With ``noise_estimated`` the walk's σ are found from the
    data (:func:`_walk_estimated`), starting from ``walk``."""
    from scipy import sparse

    idx, patch, nx, ny, phi = cones.associate(poses)
    n_patch = int(patch.max(initial=-1)) + 1
    if n_patch == 0:
        return None
    e = cones.echoes
    pose = poses[idx]
    ox, oy = transform_points(pose, e.sx[idx], e.sy[idx])
    ray = pose[:, 2] + phi
    dx, dy, r = np.cos(ray), np.sin(ray), e.range_m[idx]
    q = nx * ox + ny * oy + r * (nx * dx + ny * dy)
    before = np.clip(np.searchsorted(t_ns, e.t_ns[idx], side="right") - 1, 0, len(t_ns) - 1)
    k, w = knots.between(travel[before])  # an echo moves with the pose before it

    def turn(j: I64) -> F64:  # ∂q/∂θ of a rotation about knot j's pivot
        return np.asarray(nx * (knots.pivot[j, 1] - oy) + ny * (ox - knots.pivot[j, 0])
                          + r * (ny * dx - nx * dy))

    lo = (1 - w) * (k >= 1)  # knot 0 held at zero
    design = np.column_stack([nx * lo, ny * lo, turn(k) * lo, nx * w, ny * w, turn(k + 1) * w])
    col = np.concatenate([3 * np.maximum(k - 1, 0)[:, None] + np.arange(3),
                          3 * k[:, None] + np.arange(3)], axis=1)  # knot j's unknowns: 3(j − 1)…
    n_par = 3 * knots.stretches
    steps = knots.carried()
    floor = RandomWalk(WALK_FLOOR * walk.xy, WALK_FLOOR * walk.yaw)  # of the configured σ

    def residuals(sol: F64, weights: F64) -> F64:
        moved = q + (design * sol[col]).sum(axis=1)
        offset = (np.bincount(patch, weights * moved, n_patch)
                  / np.bincount(patch, weights, n_patch))
        return np.asarray(moved - offset[patch])

    sol, wt = np.zeros(n_par), np.ones(idx.size)
    res = residuals(sol, wt)
    scale = 1.0
    # the systems' sparsity, the same in every step
    pairs = (col[:, :, None] * n_par + col[:, None, :]).ravel()
    block_rows, block_cols = np.repeat(patch, col.shape[1]), col.ravel()
    for _ in range(IRLS_STEPS):
        sigma = MAD_SIGMA * float(np.median(np.abs(res))) + 1e-6
        scale = CAUCHY * sigma
        wt = 1.0 / (1.0 + (res / scale) ** 2) / sigma**2
        # normal equations with the offsets eliminated: Gᵀ W G − Bᵀ D⁻¹ B (+ the prior)
        wg = design * wt[:, None]
        normal = np.bincount(pairs, (wg[:, :, None] * design[:, None, :]).ravel(),
                             n_par * n_par).reshape(n_par, n_par).astype(np.float64)
        rhs = np.bincount(block_cols, (wg * q[:, None]).ravel(), n_par).astype(np.float64)
        weight = np.bincount(patch, wt, n_patch)
        # each patch's weighted design summed (sparse: a patch is seen from a few knots)
        blocks = sparse.csr_matrix((wg.ravel(), (block_rows, block_cols)),
                                   shape=(n_patch, n_par))
        wq = np.bincount(patch, wt * q, n_patch)
        normal -= (blocks.T @ sparse.diags(1.0 / weight) @ blocks).toarray()
        rhs -= blocks.T @ (wq / weight)
        if noise_estimated:
            sol, walk = _walk_estimated(normal, rhs, steps, knots, walk, floor)
        else:
            sol = _posterior(normal, rhs, steps, walk.step_sd(knots))[0]
        res = residuals(sol, wt)

    def loss(v: F64) -> float:
        return float(np.log1p((v / scale) ** 2).sum())

    none_w = np.ones(idx.size)  # no correction, the patches' offsets refitted (robustly)
    none = residuals(np.zeros(n_par), none_w)
    for _ in range(IRLS_STEPS):
        none_w = 1.0 / (1.0 + (none / scale) ** 2)
        none = residuals(np.zeros(n_par), none_w)
    corr = np.zeros((knots.stretches + 1, 3))
    corr[1:] = sol.reshape(-1, 3)
    return corr, loss(none), loss(res), n_par, walk


def _posterior(normal: F64, rhs: F64, steps: F64, sd: F64) -> tuple[F64, F64]:
    """The corrections' posterior mean and information under the random-walk prior (the
    ``steps`` of σ ``sd``)."""
    information = normal + steps.T @ (steps / sd[:, None] ** 2)
    return np.asarray(np.linalg.solve(information, -rhs), dtype=np.float64), information


def _walk_estimated(normal: F64, rhs: F64, steps: F64, knots: Knots, walk: RandomWalk,
                    floor: RandomWalk) -> tuple[F64, RandomWalk]:
    """The corrections and the random walk's σ that the data support (type-II maximum
    likelihood by expectation-maximisation, :data:`WALK_EM_STEPS` steps from ``walk``):
    each σ² the mean over the steps of ``E[step²]`` under the posterior (the estimate's
    square and its variance) per metre, position's x and y together; at least ``floor``
    (:data:`WALK_FLOOR` of the configured σ). Where the data show no heading walk (noise in
    position alone) the heading steps' σ shrinks and the run's frame stays where its first
    poses put it; a heading walk keeps it open."""
    stretch_m = knots.stretch_m
    for _ in range(WALK_EM_STEPS):
        sol, information = _posterior(normal, rhs, steps, walk.step_sd(knots))
        cov = np.linalg.inv(information)
        mean_sq = ((steps @ sol) ** 2 + ((steps @ cov) * steps).sum(axis=1)).reshape(-1, 3)
        walk = RandomWalk(
            max(math.sqrt(float(mean_sq[:, :2].mean()) / stretch_m), floor.xy),
            max(math.sqrt(float(mean_sq[:, 2].mean()) / stretch_m), floor.yaw))
    return _posterior(normal, rhs, steps, walk.step_sd(knots))[0], walk
