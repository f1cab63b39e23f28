"""Pose refinement: the odometry corrected from the sonar echoes, before mapping.

1. **Calibration** (:mod:`~pipeline.refine.calibration`, ``calibration_search``): the
   odometry's scale error and heading bias that the echoes agree on, removed by
   re-integrating the odometry with the inverse drift model.
2. **Compass** (:mod:`~pipeline.refine.compass`, ``compass``): the walls' spectrum
   overrules a heading bias whose track turns the walls off one lattice (an alias:
   calibrated again near the walls' bias), and the windows take out the heading bias left
   where the walls' directions drift along the run (the scale then found again under the
   walls' heading).
3. **Local corrections** (:mod:`~pipeline.refine.stretches`, ``local_corrections``): a
   rigid correction per stretch of travel where the surface patches that its visits share
   establish one (the odometry's random walk).

``model = "graph"`` replaces all three by graph SLAM on the echoes
(:mod:`~pipeline.refine.slam`: submaps, correlative loop closures, one pose graph with the
odometry's scale and heading bias as variables, an acceptance test).

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
from pipeline.refine.stretches import consistency_needed, correct_stretches
from pipeline.stages.pose_sync import PoseTrack


@dataclass(frozen=True)
class Refinement:
    """The refined poses (same stamps as the odometry) and what refinement did."""

    t_ns: I64
    x: F64
    y: F64
    yaw: F64
    metrics: dict[str, Any]


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
    metrics.update(_moved(tx, ty, tyaw, ox, oy, oyaw))
    metrics["summary"] = summary(metrics, cfg)
    return Refinement(tt.copy(), ox.copy(), oy.copy(), oyaw.copy(), metrics)


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
