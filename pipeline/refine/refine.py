"""Pose refinement: the odometry corrected from the sonar echoes, before mapping.

0. **Calibration** (:mod:`~pipeline.refine.calibration`, ``calibration_search``): the
   odometry's scale error and heading bias that the echoes agree on; the rest works on
   the odometry corrected by them. Then ``compass`` (:mod:`~pipeline.refine.compass`):
   the walls' spectrum overrules a heading bias whose track turns the walls off one
   lattice (an alias: calibrated again near the walls' bias), and the windows take out the
   heading bias left where the walls' directions drift along the run (the scale then
   found again under the walls' heading). Then
   ``local_corrections``
   (:mod:`~pipeline.refine.stretches`): a rigid correction per stretch of travel where the
   surface patches that its visits share establish one (the odometry's random walk). With
   ``match_submaps = false`` (the default, see below) this is the refinement.
1. **Submaps** (:mod:`~pipeline.refine.submaps`): echoes pooled over ~1.5 m of odometry.
2. **Sequential matching**: each submap is matched (:mod:`~pipeline.refine.matcher`) against
   the previous ``local_map_submaps`` submaps placed by their current estimates, around the
   odometry's prediction; a match scoring ``min_score`` or more places the submap and
   becomes a constraint on the pose graph, else the odometry's prediction is kept.
3. **Loop closures**: each submap is matched against earlier submaps (not the recent ones:
   ``loop_min_path_m`` of travel apart) whose estimated anchors lie within
   ``loop_radius_m``, nearest first, in a wider window; gated by score and ambiguity.
4. **Pose graph** (:mod:`~pipeline.refine.graph`) over odometry, matches and loop closures,
   with the odometry calibration (scale error, heading bias); matches whose χ² at the
   solution exceeds ``reject_chi2`` are dropped and the graph solved again.
5. **Back onto every pose**: the odometry re-integrated with the estimated calibration
   (:func:`pipeline.drift.apply_drift` with the inverse model), then each pose moved by
   the anchors' corrections interpolated in time (linear, shortest arc in yaw).

Steps 1-5 (``match_submaps``) are off by default: measured on the simulated office run
with 3 % scale error and 0.8°/m heading bias, the matcher's yaw errors on sonar submaps
(3-8°, against 1-2° of odometry error per submap) made the graph's result worse than the
calibrated odometry (ATE 0.31 m against 0.125 m); see benchmarks/RESULTS.md.

Everything is numpy and scipy without randomness, so the same input gives the same bytes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from pipeline.config import PoseRefinementConfig
from pipeline.drift import DriftModel, apply_drift
from pipeline.refine.calibration import (
    Calibration,
    Lean,
    calibrate,
    consistency_change,
    gate_digits,
)
from pipeline.refine.compass import (
    compass_correction,
    spectrum_turn,
    wall_chords,
    window_lattice,
)
from pipeline.refine.echoes import Echoes
from pipeline.refine.graph import (
    GraphOptions,
    MatchConstraints,
    Odometry,
    cost_at,
    solve,
    sqrt_information,
)
from pipeline.refine.matcher import LikelihoodField, Match, SearchWindow, match
from pipeline.refine.stretches import consistency_needed, correct_stretches
from pipeline.refine.submaps import Submap, build_submaps, path_length_at
from pipeline.se2 import between, compose, inverse, transform_points
from pipeline.stages.pose_sync import POSE_OK, PoseTrack, interpolate_poses


@dataclass(frozen=True)
class Refinement:
    """The refined poses (same stamps as the odometry) and what refinement did."""

    t_ns: I64
    x: F64
    y: F64
    yaw: F64
    metrics: dict[str, Any]


@dataclass
class _Constraint:
    i: int
    j: int
    z: F64
    cov: F64
    kind: str  # "sequential" or "loop"


class _Matcher:
    """Submap matching with the configured field and gates."""

    def __init__(self, cfg: PoseRefinementConfig, submaps: list[Submap]):
        self.cfg = cfg
        self.submaps = submaps
        self.step_xy = cfg.field_resolution_m
        self.seq = SearchWindow(cfg.search_xy_m, math.radians(cfg.search_yaw_deg),
                                cfg.field_resolution_m, math.radians(0.5))
        self.loop = SearchWindow(cfg.loop_search_xy_m, math.radians(cfg.loop_search_yaw_deg),
                                 2 * cfg.field_resolution_m, math.radians(1.0))

    def against(self, refs: list[int], est: F64, j: int, prediction: F64,
                window: SearchWindow) -> Match | None:
        xs, ys = [], []
        for r in refs:
            sm = self.submaps[r]
            wx, wy = transform_points(est[r], sm.px, sm.py)
            xs.append(wx)
            ys.append(wy)
        rx, ry = np.concatenate(xs), np.concatenate(ys)
        if rx.shape[0] < 3 or len(self.submaps[j]) < 3:
            return None
        cfg = self.cfg
        margin = window.xy + 3 * cfg.field_sigma_m + cfg.max_echo_range_m
        fld = LikelihoodField.of_points(rx, ry, res=cfg.field_resolution_m,
                                        sigma=cfg.field_sigma_m, margin=margin)
        q = self.submaps[j]
        return match(fld, q.px, q.py, prediction, window, temperature=0.02,
                     floor_xy=0.02, floor_yaw=math.radians(0.3),
                     distinct_m=max(0.3, 3 * cfg.field_sigma_m), distinct_rad=math.radians(8))


def _rotate_cov(cov: F64, yaw: float) -> F64:
    """A world-frame (x, y, yaw) covariance expressed in a frame rotated by ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    r = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(r @ cov @ r.T)


def configured_calibration(t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes,
                           cfg: PoseRefinementConfig, bias_centre: float = 0.0,
                           max_bias: float | None = None) -> Calibration:
    """The odometry calibration ``cfg`` asks for (:func:`pipeline.refine.calibration.calibrate`)
    from ``echoes`` out to ``max_echo_range_m``, and those out to ``calibration_far_range_m``
    for the scale where it reaches further; the heading bias within ``bias_centre ±
    max_bias`` (default: ``calibration_max_bias_deg_per_m`` about 0)."""
    far = (echoes.within(cfg.calibration_far_range_m)
           if cfg.calibration_far_range_m > cfg.max_echo_range_m else None)
    return calibrate(
        t_ns, x, y, yaw, echoes.within(cfg.max_echo_range_m),
        max_scale=cfg.calibration_max_scale,
        max_bias=(math.radians(cfg.calibration_max_bias_deg_per_m) if max_bias is None
                  else max_bias),
        bias_centre=bias_centre,
        res=cfg.field_resolution_m, sigma=cfg.field_sigma_m,
        min_gain=cfg.calibration_min_gain, strong_gain=cfg.calibration_strong_gain,
        scale_score=cfg.calibration_scale_score,
        max_slope=cfg.calibration_max_slope, min_z=cfg.calibration_scale_min_z,
        systematic=Lean(cfg.calibration_scale_systematic,
                        cfg.calibration_scale_systematic_negative),
        window_m=cfg.calibration_scale_window_m,
        tilt=cfg.calibration_scale_tilt,
        recentre=cfg.calibration_scale_recentre,
        far_echoes=far,
    )


def _turned(cal: Calibration, by: float) -> float:
    """``cal``'s heading bias turned by ``by`` (rad per metre of the track it corrects), per
    reported metre: the bias a calibration of scale 0 would apply."""
    return (cal.heading_bias + by) / (1.0 + cal.scale_error)


def _under_the_walls(t_ns: I64, x: F64, y: F64, yaw: F64, all_echoes: Echoes, echoes: Echoes,
                     cfg: PoseRefinementConfig, cal: Calibration,
                     track: tuple[F64, F64, F64], metrics: dict[str, Any]
                     ) -> tuple[Calibration, tuple[F64, F64, F64]]:
    """The calibration ``cal`` checked against the walls (:mod:`pipeline.refine.compass`),
    and the odometry it corrects (``track``: as ``cal`` corrects it): where the walls' spectrum establishes a turn beyond the
    compass's windows (an alias of the bias: the bias found and the odometry's both lie
    within ±``calibration_max_bias_deg_per_m``, their difference within twice it), or the
    windows a drift left, the calibration runs again, so that the scale is found under the
    walls' heading: near the spectrum's bias, searched within the windows' reach (the
    spectrum resolves the alias, the echoes the bias within its peak: the drifted Infinite
    Corridor's scale +3.1 % so, +2.7 % with the spectrum's bias given, F1 0.55 against 0.34
    of true poses' 0.83), and applied only where a bias there passes the echo scores'
    gates (the walls propose, the echoes accept); at the windows' bias, given (they measure
    it to ±0.003°/m on Acapulco, where the echo scores are 0.07°/m off)."""
    max_bias = math.radians(cfg.compass_max_bias_deg_per_m)

    def again(turned_by: float, within: float) -> Calibration:
        """The calibration again, its heading bias searched within ``within`` (0: given)
        of ``cal``'s turned by ``turned_by`` (rad per metre of the track ``cal`` corrects)."""
        return configured_calibration(t_ns, x, y, yaw, all_echoes, cfg, max_bias=within,
                                      bias_centre=_turned(cal, turned_by))

    chords = wall_chords(echoes, t_ns, *track)
    turn, spectrum = spectrum_turn(
        chords, max_bias=max_bias, reach=2.0 * math.radians(cfg.calibration_max_bias_deg_per_m),
        window_m=cfg.compass_window_m)
    metrics["wall_spectrum"] = spectrum
    if turn is not None:
        proposal = again(turn.bias, max_bias)  # the echoes resolve it within the peak
        if proposal.heading_bias != 0.0 or abs(_turned(cal, turn.bias)) <= max_bias:
            spectrum["overruled_deg_per_m"] = math.degrees(cal.heading_bias)
            cal = proposal
            track = cal.correct(x, y, yaw)
            chords = wall_chords(echoes, t_ns, *track)
        else:  # no bias near the walls' passes the echo scores' gates: the first stands
            spectrum["applied"] = False
            spectrum["note"] = ("not applied: no heading bias within the windows' reach of "
                                "the walls' passes the calibration's gates")
    turned = compass_correction(*track, window_lattice(chords, cfg.compass_window_m),
                                max_bias=max_bias, min_z=cfg.compass_min_z)
    metrics["compass"] = turned.metrics
    if turned.metrics["applied"]:
        cal = again(math.radians(turned.metrics["bias_left_deg_per_m"]), 0.0)
        track = cal.correct(x, y, yaw)
    return cal, track


def refine_track(track: PoseTrack, echoes: Echoes, cfg: PoseRefinementConfig) -> Refinement:
    """Refine the odometry ``track`` from ``echoes`` (see the module docstring; echoes
    beyond ``max_echo_range_m``, out to ``calibration_far_range_m``, serve the scale alone)."""
    tt = np.asarray(track.t_ns)
    tx, ty, tyaw = np.asarray(track.x), np.asarray(track.y), np.asarray(track.yaw)
    if cfg.model == "graph":
        from pipeline.refine.slam import slam_track

        gx, gy, gyaw, gm = slam_track(track, echoes, cfg)
        gm.update(_moved(tx, ty, tyaw, gx, gy, gyaw))
        gm["summary"] = graph_summary(gm)
        return Refinement(tt.copy(), gx, gy, gyaw, gm)
    all_echoes, echoes = echoes, echoes.within(cfg.max_echo_range_m)
    metrics: dict[str, Any] = {"echoes": len(echoes)}
    if cfg.calibration_search and len(echoes) >= cfg.submap_min_echoes:
        cal0 = configured_calibration(tt, tx, ty, tyaw, all_echoes, cfg)
        ox, oy, oyaw = cal0.correct(tx, ty, tyaw)
        if cfg.compass:
            cal0, (ox, oy, oyaw) = _under_the_walls(tt, tx, ty, tyaw, all_echoes, echoes, cfg,
                                                    cal0, (ox, oy, oyaw), metrics)
        if cfg.local_corrections:
            local = correct_stretches(
                tt, ox, oy, oyaw, echoes, stretch_m=cfg.local_stretch_m,
                sigma_xy=cfg.odometry_sigma_xy, sigma_yaw=math.radians(cfg.odometry_sigma_yaw_deg),
                iterations=cfg.local_iterations, min_gain=cfg.local_min_gain,
                min_consistency_gain=cfg.local_min_consistency_gain,
                strong_gain=cfg.local_strong_gain, held_out=cfg.local_held_out,
                noise_estimated=cfg.local_noise_estimated,
                res=cfg.field_resolution_m,
                sigma=cfg.field_sigma_m)
            ox, oy, oyaw = local.x, local.y, local.yaw
            metrics["local"] = local.metrics
        echoes = echoes.on_track(tt, ox, oy, oyaw)
        metrics["search_scale_error"] = cal0.scale_error
        metrics["search_heading_bias_deg_per_m"] = math.degrees(cal0.heading_bias)
        metrics["sharpness_before"] = cal0.sharpness_uncalibrated
        metrics["sharpness_after"] = cal0.sharpness
        if math.isfinite(cal0.scale_slope):
            metrics["scale_fixed_point_slope"] = cal0.scale_slope
        if math.isfinite(cal0.scale_z):
            metrics["scale_z"] = cal0.scale_z
        if math.isfinite(cal0.scale_estimate):  # applied or not (the gates: calibration.py)
            metrics["scale_estimate"] = cal0.scale_estimate
            metrics["scale_standard_error"] = cal0.scale_standard_error
            metrics["scale_far_echoes"] = cal0.scale_far_echoes
        if cal0.scale_other_model is not None:  # both patch models asked ("fallback")
            metrics["scale_patch_orientation_fitted"] = cal0.scale_oriented
            other = "offset_only" if cal0.scale_oriented else "orientation_fitted"
            metrics[f"scale_{other}_estimate"] = cal0.scale_other_model[0]
            metrics[f"scale_{other}_standard_error"] = cal0.scale_other_model[1]
        if cal0.scale_disputed_by is not None:  # the far echoes' scale that kept it out
            metrics["scale_far_estimate"] = cal0.scale_disputed_by.value
            metrics["scale_far_standard_error"] = cal0.scale_disputed_by.standard_error
        if cal0.bias_rejected is not None:  # the sharpest bias, and why it was not applied
            rejected = cal0.bias_rejected
            metrics["heading_bias_rejected"] = {
                "candidate_deg_per_m": math.degrees(rejected.candidate),
                "sharper": rejected.sharper,
                **({"more_consistent": rejected.more_consistent}
                   if math.isfinite(rejected.more_consistent) else {})}
        if math.isfinite(cal0.consistency):
            metrics["consistency_before"] = cal0.consistency_uncalibrated
            metrics["consistency_after"] = cal0.consistency
    else:
        ox, oy, oyaw = tx, ty, tyaw
    path = path_length_at(tt, ox, oy, echoes.t_ns) if len(echoes) else np.empty(0)
    submaps = build_submaps(echoes, path, travel_m=cfg.submap_travel_m,
                            min_echoes=cfg.submap_min_echoes, max_points=cfg.submap_max_points)
    metrics["submaps"] = len(submaps)
    if not cfg.match_submaps or len(submaps) < 2:
        metrics["note"] = ("fewer than 2 submaps: no matching" if cfg.match_submaps
                           else "match_submaps = false: the calibrated odometry")
        metrics.update({"matches_accepted": 0, "matches_rejected": 0,
                        "loop_closures_accepted": 0, "loop_closures_rejected": 0,
                        "cost_initial": None, "cost_final": None})
        metrics.update(_moved(tx, ty, tyaw, ox, oy, oyaw))
        metrics["summary"] = summary(metrics, cfg)
        return Refinement(tt.copy(), ox.copy(), oy.copy(), oyaw.copy(), metrics)
    n = len(submaps)
    odo_anchor = np.array([s.anchor for s in submaps])
    anchor_path = np.array([s.path_m for s in submaps])
    matcher = _Matcher(cfg, submaps)
    est = odo_anchor.copy()
    cons: list[_Constraint] = []
    seq_ok = seq_rejected = 0
    for j in range(1, n):
        pred = compose(est[j - 1], between(odo_anchor[j - 1], odo_anchor[j]))
        refs = list(range(max(0, j - cfg.local_map_submaps), j))
        m = matcher.against(refs, est, j, pred, matcher.seq)
        if m is not None and m.score >= cfg.min_score:
            est[j] = m.pose
            z = between(est[j - 1], m.pose)
            cons.append(_Constraint(j - 1, j, z, _rotate_cov(m.cov, est[j - 1][2]), "sequential"))
            seq_ok += 1
        else:
            est[j] = pred
            seq_rejected += 1
    loop_tried = loop_ok = loop_gated = 0
    for j in range(n):
        d = np.hypot(est[:j, 0] - est[j, 0], est[:j, 1] - est[j, 1])
        far_path = anchor_path[j] - anchor_path[:j] >= cfg.loop_min_path_m
        cand = np.flatnonzero((d <= cfg.loop_radius_m) & far_path)
        cand = cand[np.argsort(d[cand], kind="stable")][: cfg.loop_max_per_submap]
        for i in cand.tolist():
            loop_tried += 1
            refs = [r for r in (i - 1, i, i + 1) if 0 <= r < n and r != j]
            m = matcher.against(refs, est, j, est[j], matcher.loop)
            if m is None or m.score < cfg.min_score or m.ambiguity > cfg.max_ambiguity:
                loop_gated += 1
                continue
            z = between(est[i], m.pose)
            cons.append(_Constraint(i, j, z, _rotate_cov(m.cov, est[i][2]), "loop"))
            loop_ok += 1
    odo = Odometry(between(odo_anchor[:-1], odo_anchor[1:]), np.diff(anchor_path))
    opt = GraphOptions(cfg.odometry_sigma_xy, math.radians(cfg.odometry_sigma_yaw_deg),
                       cfg.calibrate, cfg.prior_scale, math.radians(cfg.prior_bias_deg_per_m),
                       cfg.robust_scale)
    mc = MatchConstraints(
        np.array([c.i for c in cons], np.int64), np.array([c.j for c in cons], np.int64),
        np.array([c.z for c in cons]).reshape(-1, 3),
        np.array([sqrt_information(c.cov) for c in cons]).reshape(-1, 3, 3),
    )
    kinds = np.array([c.kind for c in cons])
    cost_odometry = cost_at(odo_anchor, odo, mc, opt)
    sol = solve(est, odo, mc, opt)
    cost_initial = sol.cost_initial
    bad = sol.match_chi2 > cfg.reject_chi2
    if bad.any():
        mc = mc.take(~bad)
        sol = solve(sol.anchors, odo, mc, opt)
    rejected_seq = int((bad & (kinds == "sequential")).sum()) if kinds.size else 0
    rejected_loop = int((bad & (kinds == "loop")).sum()) if kinds.size else 0
    # Back onto every pose: calibrated odometry, then the anchors' corrections.
    inv_model = DriftModel(
        scale_error=1.0 / (1.0 + sol.scale_error) - 1.0,
        heading_bias_deg_per_m=-math.degrees(sol.heading_bias),
    )
    cx, cy, cyaw = apply_drift(ox, oy, oyaw, inv_model)
    cal = PoseTrack(tt, cx, cy, cyaw, "", "")
    t_anchor = np.array([s.t_ns for s in submaps], np.int64)
    look = interpolate_poses(cal, t_anchor, np.iinfo(np.int64).max)
    assert (look.reason == POSE_OK).all()
    cal_anchor = np.column_stack([look.x, look.y, look.yaw])
    corr = compose(sol.anchors, inverse(cal_anchor))  # world-frame correction per anchor
    corr[:, 2] = np.unwrap(corr[:, 2])
    ct = [np.interp(tt.astype(np.float64), t_anchor.astype(np.float64), corr[:, k])
          for k in range(3)]
    out = compose(np.column_stack(ct), np.column_stack([cx, cy, cyaw]))
    rx, ry, ryaw = out[:, 0].copy(), out[:, 1].copy(), wrap_angle(out[:, 2])
    metrics.update({
        "matches_accepted": seq_ok - rejected_seq,
        "matches_rejected": seq_rejected + rejected_seq,
        "loop_closures_tried": loop_tried,
        "loop_closures_accepted": loop_ok - rejected_loop,
        "loop_closures_rejected": loop_gated + rejected_loop,
        "rejected_after_solve": int(bad.sum()),
        "cost_odometry": cost_odometry,
        "cost_initial": cost_initial,
        "cost_final": sol.cost_final,
        "solver_evaluations": sol.iterations,
        "scale_error": sol.scale_error,
        "heading_bias_deg_per_m": math.degrees(sol.heading_bias),
    })
    metrics.update(_moved(tx, ty, tyaw, rx, ry, ryaw))
    metrics["summary"] = summary(metrics, cfg)
    return Refinement(tt.copy(), rx, ry, ryaw, metrics)


def graph_summary(metrics: dict[str, Any]) -> str:
    """One line on what the graph model did (``run`` prints it)."""
    head = (f"pose refinement (graph): {metrics['submaps']} submaps, "
            f"{metrics['matches_accepted']} matches, {metrics['loop_closures_accepted']} loop "
            f"closures ({metrics['loop_closures_rejected']} rejected)")
    if "scale_error" in metrics:
        head += (f"; scale error {metrics['scale_error']:+.1%}, heading bias "
                 f"{metrics['heading_bias_deg_per_m']:+.2f}°/m")
    verdict = ("accepted" if metrics["accepted"] else
               f"not accepted: {metrics.get('note', 'the odometry stays')}")
    return (f"{head}; {verdict}; poses moved {metrics.get('moved_mean_m', 0.0):.2f} m mean, "
            f"{metrics.get('moved_max_m', 0.0):.2f} m max")


def summary(metrics: dict[str, Any], cfg: PoseRefinementConfig) -> str:
    """One line on what refinement did, from its ``metrics`` (``run`` prints it): the
    scale and heading bias applied, or why the scale was not."""
    parts = []
    reach = (f", echoes to {cfg.calibration_far_range_m:g} m"
             if metrics.get("scale_far_echoes") else "")
    if metrics.get("scale_patch_orientation_fitted"):
        reach += (", patch orientations fitted; offset-only "
                  f"{metrics['scale_offset_only_estimate']:+.1%} ± "
                  f"{metrics['scale_offset_only_standard_error']:.1%}")
    if "search_heading_bias_deg_per_m" not in metrics:
        parts.append(f"no calibration ({metrics.get('echoes', 0)} echoes)")
    elif metrics.get("search_scale_error"):
        parts.append(f"scale error {metrics['search_scale_error']:+.1%} "
                     f"(z {metrics.get('scale_z', math.nan):.1f}{reach})")
    elif "scale_estimate" in metrics:
        z = metrics.get("scale_z", math.nan)
        why = (f"the far echoes disagree: {metrics['scale_far_estimate']:+.1%} ± "
               f"{metrics['scale_far_standard_error']:.1%}" if "scale_far_estimate" in metrics
               else f"z {z:.1f} < {cfg.calibration_scale_min_z:g}"
               if not z >= cfg.calibration_scale_min_z
               else f"fixed-point slope {metrics['scale_fixed_point_slope']:.2f}")
        parts.append(f"scale error not established ({metrics['scale_estimate']:+.1%} ± "
                     f"{metrics['scale_standard_error']:.1%}, {why}{reach}), not applied")
    elif "scale_fixed_point_slope" in metrics:
        parts.append("scale error undetermined (fixed-point slope "
                     f"{metrics['scale_fixed_point_slope']:.2f}), not applied")
    elif cfg.calibration_max_scale > 0 and cfg.calibration_scale_score == "surfaces":
        parts.append("scale error undetermined (no surface seen from two places), not applied")
    bias = metrics.get("search_heading_bias_deg_per_m")
    if bias:
        parts.append(f"heading bias {bias:+.2f}°/m")
    elif bias is not None:
        parts.append("no heading bias" + _why_no_bias(metrics.get("heading_bias_rejected"),
                                                      cfg.calibration_min_gain,
                                                      cfg.calibration_strong_gain))
    spectrum = metrics.get("wall_spectrum")
    if spectrum and spectrum["applied"]:
        parts.append(f"the walls overruled a heading bias of {spectrum['overruled_deg_per_m']:+.2f}°/m "
                     f"(their lattice {spectrum['strength_at_zero']:.2f} → "
                     f"{spectrum['strength']:.2f} turned by {spectrum['bias_deg_per_m']:+.2f}°/m), "
                     f"calibrated again there")
    compass = metrics.get("compass")
    if compass and compass.get("applied"):
        parts.append(f"heading drift against the walls {compass['bias_left_deg_per_m']:+.3f}°/m "
                     f"(z {compass['z']:.1f}) taken out")
    local = metrics.get("local")
    if local and "gain_per_parameter" in local:
        gain = local["gain_per_parameter"]
        if local.get("applied"):
            parts.append(f"local corrections over {local['stretches']} stretches "
                         f"({gain:.2f} per parameter)")
        elif "consistency_gain" in local:
            needed = consistency_needed(gain, cfg.local_min_consistency_gain,
                                        cfg.local_strong_gain)
            d = gate_digits(local["consistency_gain"], needed)
            if local["consistency_gain"] >= needed:  # refused by the held-out half
                held = consistency_change(local["held_out_consistency_gain"], 2)
                parts.append(f"no local corrections ({gain:.2f} per parameter, but fitted to "
                             f"half the echoes they leave the other half {held})")
            else:
                parts.append(f"no local corrections ({gain:.2f} per parameter, but the echoes "
                             f"{consistency_change(local['consistency_gain'], d)}, "
                             f"< {needed:.{d}%})")
        else:
            parts.append(f"no local corrections ({gain:.2f} < {cfg.local_min_gain:g} per "
                         "parameter)")
    if metrics.get("cost_final") is not None:
        parts.append(f"{metrics['matches_accepted']} matches, "
                     f"{metrics['loop_closures_accepted']} loop closures")
    parts.append(f"poses moved {metrics.get('moved_mean_m', 0.0):.2f} m mean, "
                 f"{metrics.get('moved_max_m', 0.0):.2f} m max")
    return "pose refinement: " + "; ".join(parts)


def _why_no_bias(rejected: dict[str, float] | None, min_gain: float,
                 strong_gain: float) -> str:
    """Why the sharpest heading bias was not applied (``metrics`` ``heading_bias_rejected``),
    as the summary's parenthesis (the gate it failed, :func:`~pipeline.refine.calibration.
    bias_accepted`); empty when the sharpest was none."""
    if not rejected:
        return ""
    head = (f" (the sharpest, {rejected['candidate_deg_per_m']:+.2f}°/m, makes the echoes "
            f"{rejected['sharper']:.1%} sharper")
    if "more_consistent" not in rejected:
        return f"{head}, < {min_gain:.0%})"
    change = consistency_change(rejected["more_consistent"])
    if rejected["sharper"] >= strong_gain:  # strongly sharper: refused for the consistency lost
        return f"{head} but {change}, ≥ {min_gain:.0%} less)"
    return f"{head} but {change}, < {min_gain:.0%})"


def _moved(x0: F64, y0: F64, a0: F64, x1: F64, y1: F64, a1: F64) -> dict[str, float]:
    d = np.hypot(x1 - x0, y1 - y0)
    da = np.degrees(np.abs(wrap_angle(a1 - a0)))
    return {
        "moved_mean_m": float(d.mean()) if d.size else 0.0,
        "moved_max_m": float(d.max()) if d.size else 0.0,
        "turned_max_deg": float(da.max()) if da.size else 0.0,
    }
