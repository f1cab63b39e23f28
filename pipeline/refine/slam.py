"""Pose refinement as one model: graph SLAM on the sonar echoes.

1. **Submaps** (:mod:`~pipeline.refine.submaps`): echoes pooled over ``submap_travel_m``
   of odometry, rigid in their anchor's frame; one more anchor, without echoes, at the
   first pose holds the graph's frame where the odometry has no error yet.
2. **Scan-to-map matching**, in travel order: submap ``j`` is correlated
   (:mod:`~pipeline.refine.correlative`) against the previous ``local_map_submaps``
   submaps placed by their estimates, around the odometry's prediction (± ``search_xy_m``,
   ``search_yaw_deg``); every optimum inside the window becomes a constraint, its
   posterior mean with its covariance plus the submaps' own odometry walk
   (:func:`distortion`): a weak match weighs little instead of passing a score gate.
3. **Loop closures**: earlier submaps (twice ``loop_radius_m`` of travel back) whose
   estimate lies within ``loop_radius_m`` are correlated over ± ``loop_search_xy_m``,
   ``loop_search_yaw_deg``; kept when the score reaches :data:`MIN_SCORE` and the best
   distinct pose's likelihood ratio stays below :data:`MAX_AMBIGUITY`. Each kept closure
   re-solves the graph, so the next search starts from the corrected estimate.
4. **Pose graph** (:mod:`~pipeline.refine.graph`): odometry (σ ``odometry_sigma_xy`` m/√m,
   ``odometry_sigma_yaw_deg`` °/√m), matches and closures under a Cauchy loss, the
   odometry's scale error and heading bias as two more variables (priors
   ``prior_scale``, ``prior_bias_deg_per_m``). After each closure and at the end the
   constraint of largest χ² beyond the 3-dof 99.9 % quantile is dropped and the graph
   solved again, one at a time until every constraint left is explained (a wrong closure
   bends the graph and raises the χ² of the right ones; it goes first).
5. **Acceptance**, two tests the solution must pass to replace the odometry: a
   likelihood ratio — were the odometry right, twice its cost minus the solution's would
   be at most χ² with the matches' effective degrees of freedom
   (:func:`~pipeline.refine.graph.match_dof`), so it must exceed that χ²'s 99 % quantile
   — and the echoes, which the graph
   never saw whole: their consistency ``H/(H+F)``
   (:class:`~pipeline.refine.scores.Consistency`) must be higher on the solution's poses
   than on the odometry's (closures that agree with each other but not with the
   building, e.g. alike rooms, bend the track and scatter the echoes).
6. **Back onto every pose**: the odometry re-integrated with the estimated calibration,
   then each pose moved by the anchors' corrections interpolated in time.

scipy's trust-region least squares (its steps from Cholesky factorisations,
:mod:`~pipeline.refine.trust_region`) solves the graph (deterministic).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formats.angles import wrap_angle
from formats.arrays import F64
from pipeline.config import PoseRefinementConfig
from pipeline.drift import DriftModel, apply_drift
from pipeline.refine.calibration import consistency_change
from pipeline.refine.correlative import Correlation, Window, correlate
from pipeline.refine.echoes import Echoes
from pipeline.refine.graph import (
    GraphOptions,
    MatchConstraints,
    Odometry,
    cost_at,
    match_dof,
    solve,
    sqrt_information,
)
from pipeline.refine.scores import MAX_ECHOES_CONSISTENCY, thin, track_consistency
from pipeline.refine.submaps import Submap, build_submaps, path_length_at
from pipeline.se2 import between, compose, inverse, transform_points
from pipeline.stages.pose_sync import POSE_OK, PoseTrack, interpolate_poses

ARC_STRIDE = 1  # the query scores every point of an echo's arc
CHI2_OUTLIER = 16.27  # χ² with 3 degrees of freedom at 99.9 %: a constraint the solution rejects
Z99 = 2.326  # the standard normal's 99 % quantile (χ²(dof) ≈ dof + z·√(2·dof))
SUBMAP_MIN_ECHOES = 60  # a shorter stretch joins the next submap (too few echoes to match)
SUBMAP_MAX_POINTS = 400  # echoes kept per submap (evenly thinned)
LOCAL_MAP_SUBMAPS = 3  # a submap is matched against this many previous ones
MIN_SCORE = 0.7  # a closure is kept when the reference explains this share of its echoes
MAX_AMBIGUITY = 0.99  # a closure whose distinct second pose is this likely is ambiguous
# Priors on the odometry's systematic error (σ): a few percent of scale and a fraction of a
# degree per metre are typical of uncalibrated wheel odometry (docs/POSE_REFINEMENT.md).
PRIOR_SCALE = 0.01
PRIOR_BIAS_DEG_PER_M = 2.0


@dataclass
class _Graph:
    submaps: list[Submap]
    odo: Odometry
    opt: GraphOptions
    est: F64
    i: list[int] = field(default_factory=list)
    j: list[int] = field(default_factory=list)
    z: list[F64] = field(default_factory=list)
    u: list[F64] = field(default_factory=list)
    loop: list[bool] = field(default_factory=list)
    scale: float = 0.0
    bias: float = 0.0

    def add(self, i: int, j: int, pose_j: F64, cov: F64, loop: bool) -> None:
        """A measured pose of anchor ``j`` (world) with the world covariance ``cov``, as a
        constraint relative to anchor ``i``'s current estimate."""
        c, s = math.cos(self.est[i][2]), math.sin(self.est[i][2])
        r = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        self.i.append(i)
        self.j.append(j)
        self.z.append(between(self.est[i], pose_j))
        self.u.append(sqrt_information(r @ cov @ r.T))
        self.loop.append(loop)

    def drop(self, keep: np.ndarray) -> None:
        """Forget the constraints not in ``keep``."""
        for name in ("i", "j", "z", "u", "loop"):
            setattr(self, name, [v for v, k in zip(getattr(self, name), keep.tolist(),
                                                   strict=True) if k])

    def constraints(self, keep: np.ndarray | None = None) -> MatchConstraints:
        mc = MatchConstraints(np.array(self.i, np.int64), np.array(self.j, np.int64),
                              np.array(self.z).reshape(-1, 3), np.array(self.u).reshape(-1, 3, 3))
        return mc if keep is None else mc.take(keep)

    def solve_upto(self, last: int, keep: np.ndarray | None = None) -> np.ndarray:
        """Solve the graph of anchors ``0..last``; the later ones follow by odometry.
        Returns the constraints' χ² at the solution."""
        mc = self.constraints(keep)
        inside = (mc.i <= last) & (mc.j <= last)
        mc = mc.take(inside)
        n = last + 1
        odo = Odometry(self.odo.delta[:last], self.odo.length[:last])
        sol = solve(self.est[:n].copy(), odo, mc, self.opt)
        self.est[:n] = sol.anchors
        self.scale, self.bias = sol.scale_error, sol.heading_bias
        ahead = calibrated(self.odo.delta[last:], self.odo.length[last:], self.scale, self.bias)
        for k in range(n, self.est.shape[0]):
            self.est[k] = compose(self.est[k - 1], ahead[k - n])
        chi2 = np.zeros(len(self.i))
        idx = np.flatnonzero(inside) if keep is None else np.flatnonzero(keep)[inside]
        chi2[idx] = sol.match_chi2
        return chi2


def distortion(anchor_path: F64, j: int, opt: GraphOptions) -> F64:
    """The covariance a rigid match of submap ``j`` against its predecessors inherits from
    the odometry inside them: each submap is pooled from ``L`` m of odometry around its
    anchor, whose random walk (σ_xy, σ_θ per √m) bends it; a rigid fit averages the walk
    over the submap's two halves (variance σ²·L/12 per submap, two submaps), and the
    heading's share moves points a quarter of a submap away laterally."""
    length = float(anchor_path[j] - anchor_path[j - 1]) if j > 0 else 0.0
    var_yaw = opt.sigma_yaw**2 * length / 6
    var_xy = opt.sigma_xy**2 * length / 6 + var_yaw * (length / 4) ** 2
    return np.diag([var_xy, var_xy, var_yaw])


def _start(tt: np.ndarray, tx: F64, ty: F64, tyaw: F64, first: Submap) -> Submap:
    """An anchor without echoes at the track's first pose, where the odometry has no error
    yet: the graph's frame is held there, not at the first submap's anchor (already
    ``submap_travel_m``/2 of drift in)."""
    empty = np.empty((0, first.px.shape[1]))
    return Submap(int(tt[0]), np.array([tx[0], ty[0], tyaw[0]]), 0.0, empty, empty.copy(),
                  np.empty(0), np.empty(0))


def _consistent(g: _Graph, last: int, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The constraints kept once every one the graph explains within χ²'s 99.9 % quantile:
    the worst is dropped and the graph solved again until none exceeds it (one at a time,
    since a wrong constraint raises the χ² of the right ones it bends); and every
    constraint's χ² at that last solution."""
    keep = keep.copy()
    while True:
        chi2 = g.solve_upto(last, keep)
        worst = int(np.argmax(np.where(keep, chi2, -1.0))) if keep.any() else -1
        if worst < 0 or chi2[worst] <= CHI2_OUTLIER:
            return keep, chi2
        keep[worst] = False


def calibrated(delta: F64, length: F64, scale: float, bias: float) -> F64:
    """Odometry steps (earlier anchor's frame) with the scale error ``scale`` and heading
    bias ``bias`` (rad per metre) taken out, as the graph's odometry residual does."""
    turn = -bias * length / 2
    c, s = np.cos(turn), np.sin(turn)
    return np.column_stack([(c * delta[:, 0] - s * delta[:, 1]) / (1 + scale),
                            (s * delta[:, 0] + c * delta[:, 1]) / (1 + scale),
                            delta[:, 2] - bias * length])


def _window(xy: float, yaw_deg: float, res: float) -> Window:
    """A search of ± ``xy`` m, ± ``yaw_deg``: its coarse level ~15 steps each side (at least
    two field cells, one degree)."""
    return Window(xy, math.radians(yaw_deg), max(2 * res, xy / 15),
                  math.radians(max(1.0, yaw_deg / 10)))


def _points(submaps: list[Submap], refs: list[int], est: F64) -> tuple[F64, F64, F64, F64]:
    """The reference submaps' arcs (echoes × arc samples) and sensors placed at ``est``."""
    parts = []
    for r in refs:
        sm = submaps[r]
        assert sm.ox is not None and sm.oy is not None
        parts.append((*transform_points(est[r], sm.px, sm.py),
                      *transform_points(est[r], sm.ox, sm.oy)))
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(4))  # type: ignore[return-value]


def _match(g: _Graph, refs: list[int], j: int, prediction: F64, window: Window,
           cfg: PoseRefinementConfig) -> Correlation | None:
    rx, ry, sx, sy = _points(g.submaps, refs, g.est)
    q = g.submaps[j]
    return correlate(rx, ry, sx, sy, q.px[:, ::ARC_STRIDE], q.py[:, ::ARC_STRIDE], prediction,
                     window,
                     res=cfg.field_resolution_m, sigma=cfg.field_sigma_m)


def slam_track(tt: np.ndarray, tx: F64, ty: F64, tyaw: F64, echoes: Echoes,
               cfg: PoseRefinementConfig, scale: float = 0.0
               ) -> tuple[F64, F64, F64, dict[str, Any]]:
    """The refined poses of the odometry ``(tt, tx, ty, tyaw)`` (same stamps; ``echoes``
    placed on it) and what the graph did. ``scale``: the odometry's scale error as the
    echoes' surfaces measured it (the scale's prior mean in the final solve: loop closures
    do not observe the scale)."""
    echoes = echoes.within(cfg.max_echo_range_m)
    path = path_length_at(tt, tx, ty, echoes.t_ns) if len(echoes) else np.empty(0)
    submaps = build_submaps(echoes, path, travel_m=cfg.submap_travel_m,
                            min_echoes=SUBMAP_MIN_ECHOES, max_points=SUBMAP_MAX_POINTS)
    metrics: dict[str, Any] = {"model": "graph", "echoes": len(echoes), "submaps": len(submaps)}
    zero = {"matches_accepted": 0, "matches_rejected": 0, "loop_closures_accepted": 0,
            "loop_closures_rejected": 0, "accepted": False}
    if len(submaps) < 2:
        metrics.update(zero, note="fewer than 2 submaps: the odometry")
        return tx.copy(), ty.copy(), tyaw.copy(), metrics
    submaps = [_start(tt, tx, ty, tyaw, submaps[0]), *submaps]
    odo_anchor = np.array([s.anchor for s in submaps])
    anchor_path = np.array([s.path_m for s in submaps])
    opt = GraphOptions(cfg.odometry_sigma_xy, math.radians(cfg.odometry_sigma_yaw_deg), True,
                       PRIOR_SCALE, math.radians(PRIOR_BIAS_DEG_PER_M), 1.0, True)
    odo = Odometry(between(odo_anchor[:-1], odo_anchor[1:]), np.diff(anchor_path))
    g = _Graph(submaps, odo, opt, odo_anchor.copy())
    seq = _window(cfg.search_xy_m, cfg.search_yaw_deg, cfg.field_resolution_m)
    wide = _window(cfg.loop_search_xy_m, cfg.loop_search_yaw_deg, cfg.field_resolution_m)
    seq_ok = seq_bad = loop_tried = loop_gated = loop_inconsistent = 0
    for j in range(1, len(submaps)):
        pred = compose(g.est[j - 1], calibrated(odo.delta[j - 1:j], odo.length[j - 1:j],
                                                g.scale, g.bias)[0])
        refs = list(range(max(0, j - LOCAL_MAP_SUBMAPS), j))
        m = _match(g, refs, j, pred, seq, cfg)
        if m is not None:  # every in-window optimum, weighed by its covariance
            g.add(j - 1, j, m.pose, m.cov + distortion(anchor_path, j, opt), loop=False)
            g.est[j] = m.pose
            seq_ok += 1
        else:
            g.est[j] = pred
            seq_bad += 1
        d = np.hypot(g.est[:j, 0] - g.est[j, 0], g.est[:j, 1] - g.est[j, 1])
        far = anchor_path[j] - anchor_path[:j] >= 2 * cfg.loop_radius_m
        cand = np.flatnonzero((d <= cfg.loop_radius_m) & far)
        cand = cand[np.argsort(d[cand], kind="stable")][:1]
        closed = False
        for i in cand.tolist():
            loop_tried += 1
            refs = [r for r in (i - 1, i, i + 1) if 0 <= r < j]
            m = _match(g, refs, j, g.est[j], wide, cfg)
            if m is None or m.score < MIN_SCORE or m.ambiguity > MAX_AMBIGUITY:
                loop_gated += 1
                continue
            g.add(i, j, m.pose, m.cov, loop=True)
            closed = True
        if closed:
            keep, _ = _consistent(g, j, np.ones(len(g.i), bool))
            if not keep.all():  # a new closure the graph so far cannot explain goes
                loop_inconsistent += int((~keep).sum())
                g.drop(keep)
    g.opt = opt = dataclasses.replace(opt, scale_centre=scale)
    keep, chi2 = _consistent(g, len(submaps) - 1, np.ones(len(g.i), bool))
    loop = np.array(g.loop, bool)
    mc = g.constraints(keep)
    cost_odometry = cost_at(odo_anchor, odo, mc, opt)
    cost_solution = _cost_with(g, mc, opt)
    # likelihood ratio: were the odometry right, 2·(its cost − the solution's) would be at
    # most χ² with as many degrees of freedom as the matches add (their effective number)
    dof = match_dof(g.est, odo, mc, opt, g.scale, g.bias)
    accepted = dof > 0 and 2 * (cost_odometry - cost_solution) > dof + Z99 * math.sqrt(2 * dof)
    metrics.update({
        "matches_accepted": int((keep & ~loop).sum()),
        "matches_rejected": seq_bad + int((~keep & ~loop).sum()),
        "loop_closures_tried": loop_tried,
        "loop_closures_accepted": int((keep & loop).sum()),
        "loop_closures_rejected": loop_gated + loop_inconsistent + int((~keep & loop).sum()),
        "loop_closures_inconsistent": loop_inconsistent + int((~keep & loop).sum()),
        "cost_odometry": cost_odometry, "cost_final": cost_solution, "match_dof": dof,
        "scale_error": g.scale, "heading_bias_deg_per_m": math.degrees(g.bias),
        "accepted": bool(accepted),
        "loop_closure_edges": [[*g.est[a, :2].tolist(), *g.est[b, :2].tolist()] for a, b, k, lp
                               in zip(g.i, g.j, keep.tolist(), g.loop, strict=True) if k and lp],
        "match_chi2_mean": float(chi2[keep].mean()) if keep.any() else None,
        "match_chi2_max": float(chi2[keep].max()) if keep.any() else None,
    })
    if not accepted:
        metrics["loop_closure_edges"] = []  # the odometry stays: no solution to draw them on
        metrics["note"] = "the graph does not explain the echoes better than the odometry"
        return tx.copy(), ty.copy(), tyaw.copy(), metrics
    rx, ry, ryaw = _onto_poses(tt, tx, ty, tyaw, submaps, g)
    scored = echoes.take(thin(len(echoes), MAX_ECHOES_CONSISTENCY))
    gain = (track_consistency(tt, rx, ry, ryaw, scored, cfg.field_resolution_m, cfg.field_sigma_m)
            / track_consistency(tt, tx, ty, tyaw, scored, cfg.field_resolution_m,
                                cfg.field_sigma_m) - 1.0)
    metrics["consistency_gain"] = gain
    if not gain > 0:
        metrics["accepted"] = False
        metrics["loop_closure_edges"] = []
        metrics["note"] = (f"the graph's poses leave the echoes {consistency_change(gain, 2)} "
                           "than the odometry")
        return tx.copy(), ty.copy(), tyaw.copy(), metrics
    return rx, ry, ryaw, metrics


def _cost_with(g: _Graph, mc: MatchConstraints, opt: GraphOptions) -> float:
    from pipeline.refine.graph import _Problem, robust_cost

    prob = _Problem(g.est, g.odo, mc, opt)
    v = np.concatenate([g.est.ravel(), [g.scale, g.bias]])
    return robust_cost(prob.residuals(v), opt.robust_scale)


def _onto_poses(tt: np.ndarray, tx: F64, ty: F64, tyaw: F64, submaps: list[Submap],
                g: _Graph) -> tuple[F64, F64, F64]:
    """Odometry re-integrated with the calibration, then moved by the anchors' corrections
    interpolated in time (linear, yaw unwrapped)."""
    cx, cy, cyaw = apply_drift(tx, ty, tyaw, DriftModel.removing(g.scale, g.bias))
    t_anchor = np.array([s.t_ns for s in submaps], np.int64)
    look = interpolate_poses(PoseTrack(tt, cx, cy, cyaw, "", ""), t_anchor,
                             np.iinfo(np.int64).max)
    assert (look.reason == POSE_OK).all()
    corr = compose(g.est, inverse(np.column_stack([look.x, look.y, look.yaw])))
    corr[:, 2] = np.unwrap(corr[:, 2])
    ct = [np.interp(tt.astype(np.float64), t_anchor.astype(np.float64), corr[:, k])
          for k in range(3)]
    out = compose(np.column_stack(ct), np.column_stack([cx, cy, cyaw]))
    return out[:, 0].copy(), out[:, 1].copy(), wrap_angle(out[:, 2])
