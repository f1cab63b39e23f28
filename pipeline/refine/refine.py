"""Pose refinement: the odometry corrected from the sonar echoes, before mapping, by one
model — the odometry's scale error and heading bias, and a pose graph over submaps of the
echoes with those two as variables (:mod:`~pipeline.refine.slam`).

1. **Calibration** (:mod:`~pipeline.refine.calibration`): the scale error and heading bias
   that the echoes of the whole run agree on best. It initialises the graph: loop closures
   are searched from the calibrated odometry, so a heading bias of a degree per metre no
   longer turns the track beyond the closures' search before the first revisit.
2. **Graph** (:mod:`~pipeline.refine.slam`): submaps, correlative sequential matches and
   loop closures, one robust pose graph with the scale and bias as two more variables, its
   solution interpolated back onto every pose; solved from the calibrated odometry and
   from the odometry as logged (two starts of the same problem: the closures found, and
   the local optimum reached, depend on the start).
3. **Choice by the echoes**: of the calibrated odometry and the graph's accepted solutions,
   the one under which the echoes are most consistent (``H/(H+F)``,
   :class:`~pipeline.refine.scores.Consistency`) replaces the odometry; a graph solution
   must beat the calibrated odometry to be taken.

``model = "chain"`` runs the chain this replaces instead (:mod:`~pipeline.refine.chain`).
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
from pipeline.refine.calibration import (
    MAX_SLOPE,
    MIN_GAIN,
    MIN_Z,
    STRONG_GAIN,
    WINDOW_M,
    Calibration,
    Lean,
    calibrate,
    consistency_change,
)
from pipeline.refine.echoes import Echoes
from pipeline.refine.scores import MAX_ECHOES_CONSISTENCY, thin, track_consistency
from pipeline.refine.threads import parallel_map
from pipeline.stages.pose_sync import PoseTrack


@dataclass(frozen=True)
class Refinement:
    """The refined poses (same stamps as the odometry) and what refinement did."""

    t_ns: I64
    x: F64
    y: F64
    yaw: F64
    metrics: dict[str, Any]


def calibration_gates() -> dict[str, Any]:
    """The calibration's acceptance as refinement runs it (:mod:`pipeline.refine.calibration`
    constants; the scale's two patch models, its window recentred)."""
    return {"min_gain": MIN_GAIN, "strong_gain": STRONG_GAIN, "max_slope": MAX_SLOPE,
            "min_z": MIN_Z, "systematic": Lean(), "window_m": WINDOW_M, "tilt": "fallback",
            "recentre": True}


def configured_calibration(t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes,
                           cfg: PoseRefinementConfig, max_bias: float | None = None,
                           **gates: Any) -> Calibration:
    """The odometry calibration (:func:`pipeline.refine.calibration.calibrate`) from
    ``echoes`` out to ``max_echo_range_m``, and those out to ``calibration_far_range_m``
    for the scale where it reaches further; the heading bias within ± ``max_bias`` (rad per
    m; default ``calibration_max_bias_deg_per_m``), the scale within
    ±``calibration_max_scale``; ``gates`` replace :func:`calibration_gates`'s or add to them
    (``bias_centre``)."""
    far = (echoes.within(cfg.calibration_far_range_m)
           if cfg.calibration_far_range_m > cfg.max_echo_range_m else None)
    return calibrate(
        t_ns, x, y, yaw, echoes.within(cfg.max_echo_range_m),
        max_scale=cfg.calibration_max_scale,
        max_bias=(math.radians(cfg.calibration_max_bias_deg_per_m) if max_bias is None
                  else max_bias),
        res=cfg.field_resolution_m, sigma=cfg.field_sigma_m, far_echoes=far,
        cluster_m=cfg.submap_travel_m, **{**calibration_gates(), **gates},
    )


_START_KEYS = ("accepted", "note", "loop_closures_accepted", "loop_closures_rejected",
               "matches_accepted", "scale_error", "heading_bias_deg_per_m", "consistency_gain",
               "consistency_gain_over_calibration")


def refine_track(track: PoseTrack, echoes: Echoes, cfg: PoseRefinementConfig) -> Refinement:
    """Refine the odometry ``track`` from ``echoes`` (see the module docstring; echoes
    beyond ``max_echo_range_m``, out to ``calibration_far_range_m``, serve the scale alone)."""
    from pipeline.refine.slam import SUBMAP_MIN_ECHOES, slam_track

    tt = np.asarray(track.t_ns)
    tx, ty, tyaw = np.asarray(track.x), np.asarray(track.y), np.asarray(track.yaw)
    near = echoes.within(cfg.max_echo_range_m)
    metrics: dict[str, Any] = {"model": "graph", "echoes": len(near)}
    best: tuple[F64, F64, F64] = (tx, ty, tyaw)
    if len(near) >= SUBMAP_MIN_ECHOES and cfg.model == "chain":
        from pipeline.refine.chain import chain_track

        cal, best, chained = chain_track(tt, tx, ty, tyaw, echoes, cfg)
        _calibration_metrics(cal, metrics)
        metrics.update(chained)
    elif len(near) >= SUBMAP_MIN_ECHOES:
        cal = configured_calibration(tt, tx, ty, tyaw, echoes, cfg)
        _calibration_metrics(cal, metrics)
        best = cal.correct(tx, ty, tyaw)
        scored = near.take(thin(len(near), MAX_ECHOES_CONSISTENCY))
        score = track_consistency(tt, *best, scored, cfg.field_resolution_m, cfg.field_sigma_m)
        starts = [("calibration", best)]
        if cal.scale_error != 0.0 or cal.heading_bias != 0.0:
            starts.append(("odometry", (tx, ty, tyaw)))
        graph: dict[str, Any] = {}
        tried: dict[str, Any] = {}
        def solved(named: tuple[str, tuple[F64, F64, F64]]
                   ) -> tuple[F64, F64, F64, dict[str, Any]]:
            name, start = named
            return slam_track(tt, *start, near.on_track(tt, *start), cfg,
                              scale=0.0 if name == "calibration" else cal.scale_error)

        for (name, _), (gx, gy, gyaw, gm) in zip(starts, parallel_map(solved, starts),
                                                 strict=True):  # the two starts side by side
            gm["start"] = name
            tried[name] = gm
            if gm["accepted"]:
                mine = track_consistency(tt, gx, gy, gyaw, scored, cfg.field_resolution_m,
                                         cfg.field_sigma_m)
                gm["consistency_gain_over_calibration"] = mine / score - 1.0
                if mine > score:
                    best, score, graph = (gx, gy, gyaw), mine, gm
                    continue
                gm["accepted"] = False
                gm["loop_closure_edges"] = []
                gm["note"] = "the echoes are less consistent than on the calibrated odometry"
            graph = graph or gm
        metrics.update(graph)
        metrics["starts"] = {name: {k: gm[k] for k in _START_KEYS if k in gm}
                             for name, gm in tried.items()}
    else:
        metrics.update(submaps=0, matches_accepted=0, matches_rejected=0,
                       loop_closures_accepted=0, loop_closures_rejected=0, accepted=False,
                       note=f"too few echoes ({len(near)})")
    ox, oy, oyaw = best
    metrics.update(_moved(tx, ty, tyaw, ox, oy, oyaw))
    metrics["summary"] = summary(metrics, cfg)
    return Refinement(tt.copy(), ox.copy(), oy.copy(), oyaw.copy(), metrics)


def _calibration_metrics(cal: Calibration, metrics: dict[str, Any]) -> None:
    """What the calibration found, into ``metrics``."""
    metrics["search_scale_error"] = cal.scale_error
    metrics["search_heading_bias_deg_per_m"] = math.degrees(cal.heading_bias)
    metrics["sharpness_before"] = cal.sharpness_uncalibrated
    metrics["sharpness_after"] = cal.sharpness
    if math.isfinite(cal.scale_slope):
        metrics["scale_fixed_point_slope"] = cal.scale_slope
    if math.isfinite(cal.scale_z):
        metrics["scale_z"] = cal.scale_z
    if not math.isnan(cal.scale_consistency_z):  # the echoes' test of an established scale
        metrics["scale_consistency_z"] = cal.scale_consistency_z
    if math.isfinite(cal.scale_estimate):  # applied or not (the gates: calibration.py)
        metrics["scale_estimate"] = cal.scale_estimate
        metrics["scale_standard_error"] = cal.scale_standard_error
        metrics["scale_far_echoes"] = cal.scale_far_echoes
    if cal.scale_other_model is not None:  # both patch models asked ("fallback")
        metrics["scale_patch_orientation_fitted"] = cal.scale_oriented
        other = "offset_only" if cal.scale_oriented else "orientation_fitted"
        metrics[f"scale_{other}_estimate"] = cal.scale_other_model[0]
        metrics[f"scale_{other}_standard_error"] = cal.scale_other_model[1]
    if cal.scale_disputed_by is not None:  # the far echoes' scale that kept it out
        metrics["scale_far_estimate"] = cal.scale_disputed_by.value
        metrics["scale_far_standard_error"] = cal.scale_disputed_by.standard_error
    if cal.bias_rejected is not None:  # the sharpest bias, and why it was not applied
        rejected = cal.bias_rejected
        metrics["heading_bias_rejected"] = {
            "candidate_deg_per_m": math.degrees(rejected.candidate),
            "sharper": rejected.sharper,
            **({"more_consistent": rejected.more_consistent}
               if math.isfinite(rejected.more_consistent) else {})}
    if math.isfinite(cal.consistency):
        metrics["consistency_before"] = cal.consistency_uncalibrated
        metrics["consistency_after"] = cal.consistency


def graph_clause(metrics: dict[str, Any]) -> str:
    """What the graph did, for the summary line."""
    head = (f"graph from the {metrics.get('start', 'odometry')}: {metrics['submaps']} submaps, "
            f"{metrics['matches_accepted']} matches, {metrics['loop_closures_accepted']} loop "
            f"closures ({metrics['loop_closures_rejected']} rejected)")
    if metrics["accepted"]:
        return (f"{head}, scale error {metrics['scale_error']:+.1%} and heading bias "
                f"{metrics['heading_bias_deg_per_m']:+.2f}°/m more, applied")
    return f"{head}, not applied: {metrics.get('note', 'the odometry stays')}"


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
        echoes = (f", the echoes {metrics['scale_consistency_z']:.1f} errors more consistent"
                  if "scale_consistency_z" in metrics else "")
        parts.append(f"scale error {metrics['search_scale_error']:+.1%} "
                     f"(z {metrics.get('scale_z', math.nan):.1f}{echoes}{reach})")
    elif "scale_estimate" in metrics:
        z = metrics.get("scale_z", math.nan)
        cz = metrics.get("scale_consistency_z", math.nan)
        why = (f"the far echoes disagree: {metrics['scale_far_estimate']:+.1%} ± "
               f"{metrics['scale_far_standard_error']:.1%}" if "scale_far_estimate" in metrics
               else f"z {z:.1f}, but the echoes are not more consistent under it: "
               f"{cz:.1f} errors < {MIN_Z:g}" if "scale_consistency_z" in metrics
               else f"z {z:.1f} < {MIN_Z:g}"
               if not z >= MIN_Z
               else f"fixed-point slope {metrics['scale_fixed_point_slope']:.2f}")
        parts.append(f"scale error not established ({metrics['scale_estimate']:+.1%} ± "
                     f"{metrics['scale_standard_error']:.1%}, {why}{reach}), not applied")
    elif "scale_fixed_point_slope" in metrics:
        parts.append("scale error undetermined (fixed-point slope "
                     f"{metrics['scale_fixed_point_slope']:.2f}), not applied")
    elif cfg.calibration_max_scale > 0:
        parts.append("scale error undetermined (no surface seen from two places), not applied")
    bias = metrics.get("search_heading_bias_deg_per_m")
    if bias:
        parts.append(f"heading bias {bias:+.2f}°/m")
    elif bias is not None:
        parts.append("no heading bias" + _why_no_bias(metrics.get("heading_bias_rejected"),
                                                      MIN_GAIN,
                                                      STRONG_GAIN))
    if "submaps" in metrics:
        parts.append(graph_clause(metrics))
    elif metrics.get("model") == "chain":
        local = metrics.get("local", {})
        parts.append("chain: compass " + ("applied" if metrics.get("compass", {}).get("applied")
                                          else "not applied") + ", local corrections "
                     + ("applied" if local.get("applied") else "not applied"))
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
