"""The chain that preceded the one model (``[pose_refinement] model = "chain"``), kept for
comparison until the graph matches it on every row (docs/POSE_REFINEMENT.md, "Current results"):
the calibration, then the walls as a compass (:mod:`~pipeline.refine.compass`: the walls'
spectrum overrules an aliased heading bias, their windows take out a drift left), then
local corrections per stretch of travel (:mod:`~pipeline.refine.stretches`). Its former
keys are the constants below, at the values they had as defaults; delete this module,
``compass.py`` and ``stretches.py`` together with the ``model`` key."""

from __future__ import annotations

import math
from typing import Any

from formats.arrays import F64, I64
from pipeline.config import PoseRefinementConfig
from pipeline.refine.calibration import Calibration
from pipeline.refine.compass import (
    compass_correction,
    spectrum_turn,
    wall_chords,
    window_lattice,
)
from pipeline.refine.echoes import Echoes
from pipeline.refine.stretches import correct_stretches

STRETCH_M = 20.0  # local corrections: a knot per this much travel, m
ITERATIONS = 4  # ... solves, each after associating again
MIN_GAIN = 0.5  # ... applied when the patches' loss falls by this per parameter
MIN_CONSISTENCY_GAIN = 0.01  # ... and the echoes become this much more consistent
STRONG_GAIN = 4.0  # ... or no less consistent where the loss falls by this per parameter
COMPASS_WINDOW_M = 20.0  # the walls' directions measured per this much travel, m
COMPASS_MAX_BIAS_DEG_PER_M = 0.15  # a drift against the walls searched in ± this
COMPASS_MIN_Z = 4.0  # ... applied at this many standard errors from 0


def _calibration(t_ns: I64, x: F64, y: F64, yaw: F64, echoes: Echoes,
                 cfg: PoseRefinementConfig, bias_centre: float = 0.0,
                 max_bias: float | None = None) -> Calibration:
    """The calibration refinement runs, its heading bias within ``bias_centre ± max_bias``."""
    from pipeline.refine.refine import configured_calibration

    return configured_calibration(t_ns, x, y, yaw, echoes, cfg, max_bias=max_bias,
                                  bias_centre=bias_centre)


def _turned(cal: Calibration, by: float) -> float:
    """``cal``'s heading bias turned by ``by`` (rad per metre of the track it corrects), per
    reported metre."""
    return (cal.heading_bias + by) / (1.0 + cal.scale_error)


def _under_the_walls(t_ns: I64, x: F64, y: F64, yaw: F64, all_echoes: Echoes, echoes: Echoes,
                     cfg: PoseRefinementConfig, cal: Calibration,
                     track: tuple[F64, F64, F64], metrics: dict[str, Any]
                     ) -> tuple[Calibration, tuple[F64, F64, F64]]:
    """The calibration checked against the walls (the spectrum, then the windows), and the
    odometry it corrects."""
    max_bias = math.radians(COMPASS_MAX_BIAS_DEG_PER_M)

    def again(turned_by: float, within: float) -> Calibration:
        return _calibration(t_ns, x, y, yaw, all_echoes, cfg, max_bias=within,
                            bias_centre=_turned(cal, turned_by))

    chords = wall_chords(echoes, t_ns, *track)
    turn, spectrum = spectrum_turn(
        chords, max_bias=max_bias, reach=2.0 * math.radians(cfg.calibration_max_bias_deg_per_m),
        window_m=COMPASS_WINDOW_M)
    metrics["wall_spectrum"] = spectrum
    if turn is not None:
        proposal = again(turn.bias, max_bias)
        if proposal.heading_bias != 0.0 or abs(_turned(cal, turn.bias)) <= max_bias:
            spectrum["overruled_deg_per_m"] = math.degrees(cal.heading_bias)
            cal = proposal
            track = cal.correct(x, y, yaw)
            chords = wall_chords(echoes, t_ns, *track)
        else:
            spectrum["applied"] = False
    turned = compass_correction(*track, window_lattice(chords, COMPASS_WINDOW_M),
                                max_bias=max_bias, min_z=COMPASS_MIN_Z)
    metrics["compass"] = turned.metrics
    if turned.metrics["applied"]:
        cal = again(math.radians(turned.metrics["bias_left_deg_per_m"]), 0.0)
        track = cal.correct(x, y, yaw)
    return cal, track


def chain_track(t_ns: I64, x: F64, y: F64, yaw: F64, all_echoes: Echoes,
                cfg: PoseRefinementConfig) -> tuple[Calibration, tuple[F64, F64, F64],
                                                    dict[str, Any]]:
    """The chain's calibration, corrected track and metrics (``compass``, ``local``)."""
    echoes = all_echoes.within(cfg.max_echo_range_m)
    metrics: dict[str, Any] = {"model": "chain"}
    cal = _calibration(t_ns, x, y, yaw, all_echoes, cfg)
    track = cal.correct(x, y, yaw)
    cal, track = _under_the_walls(t_ns, x, y, yaw, all_echoes, echoes, cfg, cal, track, metrics)
    local = correct_stretches(
        t_ns, *track, echoes, stretch_m=STRETCH_M, sigma_xy=cfg.odometry_sigma_xy,
        sigma_yaw=math.radians(cfg.odometry_sigma_yaw_deg), iterations=ITERATIONS,
        min_gain=MIN_GAIN, min_consistency_gain=MIN_CONSISTENCY_GAIN, strong_gain=STRONG_GAIN,
        held_out="gate", noise_estimated=True, res=cfg.field_resolution_m,
        sigma=cfg.field_sigma_m)
    metrics["local"] = local.metrics
    return cal, (local.x, local.y, local.yaw), metrics
