"""The calibration's search and gates (pipeline.refine.calibration): a heading bias applied
only where the two scores allow it (lattices, aliases, yaw noise alone), a scale only where
the surface patches establish it, the far echoes and the second patch model where their
tests pass. The scores themselves: test_scores.py."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from formats import open_log
from formats.presets import PRESETS
from pipeline.config import Config
from pipeline.refine import Echoes, collect_echoes
from pipeline.refine.calibration import MIN_GAIN, STRONG_GAIN
from pipeline.refine.scores import Consistency, Sharpness
from pipeline.refine.surfaces import FixedPoint, SurfaceScale
from pipeline.tools.simulate import SimOptions, simulate, write_simulation

SampleEchoes = Callable[[str, float], tuple[tuple[np.ndarray, ...], Echoes]]


def test_far_echoes_replace_the_near_ones_only_when_they_agree() -> None:
    from pipeline.refine.calibration import _far_agrees
    from pipeline.refine.surfaces import FixedPoint

    def fp(value: float, error: float) -> FixedPoint:
        return FixedPoint(value, 0.4, (), error)

    # the drifted Freiburg 101: +4.2 ± 0.7 % near, +3.4 ± 0.24 % to 5 m
    assert _far_agrees(fp(0.0421, 0.0067), fp(0.0344, 0.0024))
    # the corridor's true poses: the far echoes widen the error (they lean, not inform)
    assert not _far_agrees(fp(0.0071, 0.0104), fp(-0.0305, 0.0152))
    # the drifted Örebro: 1.8 % apart, 2.4 errors of the difference (√(1.75² − 1.58²) %)
    assert not _far_agrees(fp(0.0241, 0.0175), fp(0.0422, 0.0158))
    assert _far_agrees(fp(0.0241, 0.0175), fp(0.0341, 0.0158))  # 1.3 errors
    assert not _far_agrees(fp(math.nan, math.nan), fp(0.03, 0.002))


def _gated(estimate: float, error: float, applied: bool) -> Any:
    from pipeline.refine.calibration import Calibration

    return Calibration(estimate if applied else 0.0, 0.014, scale_estimate=estimate,
                       scale_standard_error=error)


@pytest.mark.parametrize(("offset", "oriented", "oriented_applied"), [
    # Örebro with 3 % and 0.8°/m: the offset-only model short of its gate, the oriented
    # one established and 0.2 errors away: its scale is applied
    ((0.0272, 0.0144), (0.0306, 0.0066), True),
    # the corridor seen by the 8 front sonars, true poses: the oriented model establishes
    # a lean of the other sign, 3.8 errors away: nothing applied
    ((0.0213, 0.0132), (-0.0312, 0.0044), False),
    # of ±0.85 % (√(0.6² + 0.6²)) apart: 1.6 % (1.9 errors) lets it in, 1.8 % (2.1) does not
    ((0.0100, 0.0060), (0.0260, 0.0060), True),
    ((0.0100, 0.0060), (0.0280, 0.0060), False),
    # undetermined by the offset-only model: nothing to agree with
    ((math.nan, math.nan), (0.0306, 0.0066), False),
])
def test_the_oriented_patches_scale_is_the_fallback_where_the_models_agree(
        offset: tuple[float, float], oriented: tuple[float, float],
        oriented_applied: bool) -> None:
    from pipeline.refine.calibration import Lean, _patch_models

    asked: list[bool] = []

    def surfaces(tilt: bool) -> Any:
        asked.append(tilt)
        return _gated(*(oriented if tilt else offset), applied=tilt)

    got = _patch_models(surfaces, "fallback", Lean(), 3.0)
    assert asked == [False, True]
    assert got.scale_oriented is oriented_applied
    if oriented_applied:
        assert got.scale_error == oriented[0]
        assert got.scale_other_model == offset
    else:
        assert got.scale_error == 0.0
        assert got.scale_estimate == offset[0] or math.isnan(offset[0])
        assert got.scale_other_model == oriented


def test_an_established_offset_only_scale_is_not_asked_again() -> None:
    from pipeline.refine.calibration import Lean, _patch_models

    asked: list[bool] = []

    def surfaces(tilt: bool) -> Any:
        asked.append(tilt)
        return _gated(0.028, 0.008, applied=True)

    assert _patch_models(surfaces, "fallback", Lean(), 3.0).scale_error == 0.028
    assert asked == [False]
    asked.clear()
    always = _patch_models(surfaces, "always", Lean(), 3.0)
    assert always.scale_oriented and always.scale_other_model is None
    assert asked == [True]
    asked.clear()
    assert not _patch_models(surfaces, "off", Lean(), 3.0).scale_oriented
    assert asked == [False]


@pytest.fixture(scope="module")
def pillar_hall(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[object, Echoes]]:
    """The hall of pillars (sample_logs/worlds/pillars.toml), true and with 3 % / 0.8°/m."""
    from pipeline.run import prepare
    from pipeline.tools.simulate import load_waypoints
    from pipeline.tools.simulate.world import load_world

    worlds = Path(__file__).resolve().parents[3] / "sample_logs" / "worlds"
    world, route = load_world(worlds / "pillars.toml"), load_waypoints(worlds / "pillars.waypoints.csv")
    runs = {}
    for name, scale, bias, mounts in (("true", 0.0, 0.0, None), ("drifted", 0.03, 0.8, None),
                                      ("drifted, 8 sonars", 0.03, 0.8, PRESETS["udacity-8sonar"])):
        sim = simulate(world, route, SimOptions(sonar_model="ideal", seed=1, speed=0.5, ring_rate_hz=5.0,
                                                drift_scale=scale,
                                                drift_heading_bias_deg_per_m=bias,
                                                **({"mounts": mounts} if mounts else {})))
        log = tmp_path_factory.mktemp("pillars") / "hall.mcap"
        write_simulation(sim, log, "mcap")
        cfg = Config()
        with open_log(log, cfg) as reader:
            sv, sensors, _ = prepare(reader, cfg)
            runs[name] = sv.track, collect_echoes(
                sv.ordered_ranges(reader), sv.track, sensors, eps_max=cfg.mapper.eps_max,
                max_echo_range_m=3.0, arc_fraction=0.8, time_offset_ns=0, max_gap_ns=10**9)
    return runs


@pytest.mark.parametrize(("sharper", "more_consistent", "accepted"), [
    (0.20, 0.05, True),  # a drift's bias: sharper and more consistent
    (0.005, 0.05, False),  # not sharper by 1 %
    (0.037, -0.02, False),  # a lattice's alias (the orchard's true poses)
    (0.037, 0.005, False),  # sharper, but under the strong gain, and not more consistent
    (0.194, -0.001, True),  # Belgioioso drifted: strongly sharper, the consistency level
    (0.194, -0.02, False),  # strongly sharper, but less consistent by more than 1 %
    (0.10, -0.0099, True),  # at the strong gain exactly
])
def test_a_bias_is_applied_when_both_gain_or_the_sharpness_gains_strongly_and_holds(
        sharper: float, more_consistent: float, accepted: bool) -> None:
    from pipeline.refine.calibration import bias_accepted

    assert bias_accepted(sharper, more_consistent, MIN_GAIN,
                         STRONG_GAIN) is accepted
    # with no strong gain (inf) only the first test remains
    assert bias_accepted(sharper, more_consistent, 0.01, math.inf) is (
        sharper >= 0.01 and more_consistent >= 0.01)


@pytest.mark.parametrize(("sharper", "more_consistent", "accepted"), [
    (0.01, 0.05, True),  # sharper and more consistent
    (-0.019, 0.17, True),  # the pillar hall's right bias: less sharp, strongly more consistent
    (-0.05, 0.23, True),  # the warehouse's
    (-0.014, 0.035, False),  # yaw noise's alias on Belgioioso (-1.65°/m)
    (-0.032, 0.057, False),  # ... on FHW (+0.03°/m)
    (0.02, 0.005, False),  # not more consistent by 1 %
])
def test_a_bias_by_consistency_the_sharpness_contradicts_must_be_strongly_more_consistent(
        sharper: float, more_consistent: float, accepted: bool) -> None:
    from pipeline.refine.calibration import consistent_bias_accepted

    assert consistent_bias_accepted(sharper, more_consistent, MIN_GAIN,
                                    STRONG_GAIN) is accepted


def test_a_lattice_whose_right_bias_is_less_sharp_is_calibrated_by_consistency(
        pillar_hall: dict[str, tuple[object, Echoes]]) -> None:
    # Rows of pillars: under the drift's own bias the echoes are *less* sharp than under
    # none (measured −1.9 %) but far more consistent (+17 %); the consistency scan finds it.
    from pipeline.refine.calibration import calibrate

    for name, want in (("drifted", 0.8), ("true", 0.0)):
        track, echoes = pillar_hall[name]
        t, x, y, yaw = (np.asarray(getattr(track, a)) for a in ("t_ns", "x", "y", "yaw"))
        if name == "drifted":
            sharp = Sharpness(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
            consistent = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
            assert sharp(0.0, math.radians(want)) < sharp(0.0, 0.0)
            assert consistent(0.0, math.radians(want)) > 1.1 * consistent(0.0, 0.0)
        strong = STRONG_GAIN
        cal = calibrate(t, x, y, yaw, echoes, max_scale=0.0, max_bias=math.radians(3.0),
                        res=0.05, sigma=0.1, min_gain=0.01, strong_gain=strong)
        assert math.degrees(cal.heading_bias) == pytest.approx(want, abs=0.05)
        if name == "drifted":  # measured 1.0 % less sharp, 20 % more consistent: strong
            never = calibrate(t, x, y, yaw, echoes, max_scale=0.0, max_bias=math.radians(3.0),
                              res=0.05, sigma=0.1, min_gain=0.01, strong_gain=1e9)
            assert never.heading_bias == 0.0


def test_an_alias_sharpness_accepts_loses_to_the_more_consistent_bias_elsewhere(
        pillar_hall: dict[str, tuple[object, Echoes]]) -> None:
    # The hall seen by 8 sonars: the sharpest bias is an alias (near −2°/m, sharper and
    # more consistent than none, so it passes both gates: measured −2.06°/m applied, ATE
    # 2.1 → 6.7 m); the consistency scan's bias near the truth is more consistent still.
    from pipeline.refine.calibration import calibrate

    track, echoes = pillar_hall["drifted, 8 sonars"]
    t, x, y, yaw = (np.asarray(getattr(track, a)) for a in ("t_ns", "x", "y", "yaw"))
    consistent = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
    assert consistent(0.0, math.radians(0.8)) > consistent(0.0, math.radians(-2.06))
    for strong in (math.inf, STRONG_GAIN):
        cal = calibrate(t, x, y, yaw, echoes, max_scale=0.0, max_bias=math.radians(3.0),
                        res=0.05, sigma=0.1, min_gain=0.01, strong_gain=strong)
        assert math.degrees(cal.heading_bias) == pytest.approx(0.8, abs=0.05)


def test_a_scale_is_established_only_clear_of_zero_flat_and_of_the_sign_asked() -> None:
    from pipeline.refine.calibration import Lean, _established
    from pipeline.refine.surfaces import FixedPoint

    def fp(value: float, error: float, slope: float = 0.5) -> FixedPoint:
        return FixedPoint(value, slope, (), error)

    lean = Lean(0.005, 0.005)
    assert _established(fp(0.047, 0.0016), 0.053, lean, 3.0, 0.75)  # the office at +5 %
    assert not _established(fp(0.007, 0.0042), 0.046, lean, 3.0, 0.75)  # z 1.1
    assert not _established(fp(-0.047, 0.0016), 0.053, lean, 3.0, 0.75)  # the other sign
    assert not _established(fp(0.047, 0.0016, slope=0.8), 0.053, lean, 3.0, 0.75)
    assert not _established(fp(math.nan, math.nan), 0.05, lean, 3.0, 0.75)


@pytest.mark.parametrize(("oriented", "applied"), [
    ((-0.022, 0.0030), -0.022),  # established and agreeing: the oriented scale
    ((-0.010, 0.0060), -0.015),  # not established: the offset-only one
    ((+0.020, 0.0030), -0.015),  # established, disagreeing: the offset-only one
])
def test_a_negative_scale_only_the_lower_lean_establishes_asks_the_oriented_patches(
        oriented: tuple[float, float], applied: float) -> None:
    """The hospital's −2 % with 0.01 m/√m: −1.5 ± 0.35 % offset-only (z 3.3 with the lower
    lean, 2.5 with the upper), −2.2 ± 0.3 % oriented."""
    from pipeline.refine.calibration import Lean, _patch_models

    asked: list[bool] = []

    def surfaces(tilt: bool) -> Any:
        asked.append(tilt)
        return (_gated(*oriented, applied=abs(oriented[0]) / oriented[1] > 3) if tilt
                else _gated(-0.015, 0.0035, applied=True))

    got = _patch_models(surfaces, "fallback", Lean(), 3.0)
    assert asked == [False, True]
    assert got.scale_error == applied and got.scale_oriented is (applied == oriented[0])
    asked.clear()
    # a scale as far below 0 that the upper lean would establish too is not asked again
    assert _patch_models(lambda tilt: asked.append(tilt) or _gated(-0.03, 0.0035, True),
                         "fallback", Lean(), 3.0).scale_error == -0.03
    assert asked == [False]


def test_the_lean_is_one_sided() -> None:
    """The estimator leans mostly towards a shorter path (a positive scale) on right
    odometry, so a negative estimate needs a smaller lean term beside its error: the skewed
    floor's −2 % with 0.01 m/√m of noise, found at −1.4 ± 0.2 %, is established by the
    default lean and was not by 0.5 % on both sides; a true-pose estimate of the same
    size above 0 is not, nor the largest lean below 0 measured (the slow-odometry
    sample's −0.71 ± 0.08 %)."""
    from pipeline.refine.calibration import Lean, _established, scale_z
    from pipeline.refine.surfaces import FixedPoint

    def fp(value: float, error: float) -> FixedPoint:
        return FixedPoint(value, 0.5, (), error)

    lean = Lean()  # the configuration's default
    assert (lean.up, lean.down) == (0.005, 0.003)
    noisy = fp(-0.014, 0.002)
    assert scale_z(noisy, lean) == pytest.approx(0.014 / math.hypot(0.002, 0.003))
    assert _established(noisy, noisy.value, lean, 3.0, 0.75)
    assert not _established(noisy, noisy.value, Lean(0.005, 0.005), 3.0, 0.75)  # z 2.6
    leaning = fp(0.014, 0.002)
    assert scale_z(leaning, lean) == pytest.approx(0.014 / math.hypot(0.002, 0.005))
    assert not _established(leaning, leaning.value, lean, 3.0, 0.75)
    assert not _established(fp(-0.0071, 0.0008), -1.0, lean, 3.0, 0.75)  # z 2.3


@pytest.mark.parametrize(("far", "applied"), [
    # Freiburg 101's real odometry: the far scale, the more precise, establishes none
    ((0.0071, 0.0042), None),
    # as the warehouse seen by the 8 front sonars (+5.0 ± 0.6 % near, +3.4 ± 0.3 % far, of
    # 3 %): the far scale, the more precise, establishes one, and it is the answer
    ((0.0200, 0.0020), 0.0200),
])
def test_disagreeing_more_precise_far_echoes_give_the_scale_where_they_establish_one(
        far: tuple[float, float], applied: float | None, sample_echoes: SampleEchoes,
        monkeypatch: pytest.MonkeyPatch) -> None:
    # The far echoes more precise than the near ones (z 3.4 here) and 2.1-3.3 errors of the
    # difference apart (the specification test fails): one of the two is misled; the far
    # scale is applied where it stands clear of 0 by itself, else none, and the far one
    # is reported as the near one's dispute.
    import pipeline.refine.calibration as calibration
    import pipeline.refine.surfaces as surfaces
    from pipeline.refine.calibration import calibrate

    track, wide = sample_echoes("office", 5.0)
    near = wide.take(np.flatnonzero(wide.range_m <= 3.0))
    near_fp = surfaces.FixedPoint(0.046, 0.5, (), 0.0125)
    far_fp = surfaces.FixedPoint(far[0], 0.5, (), far[1])
    monkeypatch.setattr(calibration, "fixed_points", lambda ests: [
        far_fp if len(est.echoes) == len(wide) else near_fp for est in ests])
    # the office's true poses: the echoes' own test of a scale (scripted here, these are
    # the near and far rules) would refuse any (test_surfaces.py tests it)
    monkeypatch.setattr(Consistency, "more_consistent_z", lambda *_: math.inf)
    cal = calibrate(*track, near, max_scale=0.05, max_bias=math.radians(3.0), res=0.05,
                    sigma=0.1, min_gain=0.01, far_echoes=wide)
    if applied is None:
        assert cal.scale_far_echoes is False and cal.scale_estimate == pytest.approx(0.046)
        assert cal.scale_error == 0.0 and cal.scale_disputed_by is far_fp
    else:
        assert cal.scale_far_echoes is True and cal.scale_disputed_by is None
        assert cal.scale_error == pytest.approx(applied)


@pytest.mark.parametrize(("name", "used"), [("office", True), ("corridor", False)])
def test_the_far_echoes_scale_is_used_where_it_passes(name: str, used: bool,
                                                     sample_echoes: SampleEchoes) -> None:
    # True poses: the office's walls seen to 5 m narrow the error (0.25 → 0.17 %); the
    # corridor's far echoes (fore and aft sonars at its pillars and end walls) widen it.
    from pipeline.refine.calibration import calibrate

    track, far = sample_echoes(name, 5.0)
    near = far.take(np.flatnonzero(far.range_m <= 3.0))
    kwargs = dict(max_scale=0.05, max_bias=math.radians(3.0), res=0.05, sigma=0.1,
                  min_gain=0.01)
    alone = calibrate(*track, near, **kwargs)
    cal = calibrate(*track, near, far_echoes=far, **kwargs)
    assert cal.scale_far_echoes is used
    assert (cal.scale_error, cal.heading_bias) == (0.0, 0.0)  # true poses: nothing applied
    if used:
        assert cal.scale_standard_error < 0.8 * alone.scale_standard_error
    else:
        assert (cal.scale_estimate, cal.scale_standard_error) == (
            alone.scale_estimate, alone.scale_standard_error)


def test_a_lattice_that_sharpens_under_a_wrong_bias_keeps_its_true_heading(
        sample_echoes: SampleEchoes) -> None:
    # The orchard sample (true poses, rows of trunks 3 m apart, 1.5 m along a row): the
    # echoes sharpen by over 1 % under +0.2°/m (an alias of the lattice), which would cost
    # the map 0.36 F1; they are less consistent there, so no bias is applied.
    from pipeline.refine.calibration import calibrate

    (t, x, y, yaw), echoes = sample_echoes("orchard", 3.0)
    alias = math.radians(0.2)
    sharp = Sharpness(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
    consistent = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
    assert sharp(0.0, alias) > 1.01 * sharp(0.0, 0.0)  # measured +3.5 %
    assert consistent(0.0, alias) < consistent(0.0, 0.0)  # measured 0.98 of none
    strong = STRONG_GAIN
    for max_scale in (0.0, 0.05):
        cal = calibrate(t, x, y, yaw, echoes, max_scale=max_scale, max_bias=math.radians(3.0),
                        res=0.05, sigma=0.1, min_gain=0.01, strong_gain=strong)
        assert (cal.scale_error, cal.heading_bias) == (0.0, 0.0)
        # ... and the calibration says which bias it turned down, and why
        rejected = cal.bias_rejected
        assert rejected is not None
        assert math.degrees(rejected.candidate) == pytest.approx(0.23, abs=0.05)
        assert rejected.sharper > 0.01 > rejected.more_consistent  # measured +3.7 %, -2.4 %


def test_a_strongly_sharper_bias_is_applied_where_the_consistency_stays_level(
        tmp_path: Path) -> None:
    # Belgioioso castle (Radish), drifted as make compare drifts its buildings: the
    # sharpest bias, +0.78°/m, sharpens the echoes by ~19 % and leaves them ~0.1 % less
    # consistent. The first test alone refused it (refined F1 0.09 of the true poses');
    # the strong-sharpness route applies it, the drift's 3 % and 0.8°/m found.
    from pipeline.drift import DriftModel
    from pipeline.refine.refine import configured_calibration
    from pipeline.stages.pose_sync import pose_gap_limit_s
    from pipeline.tools.emulate import EmulateOptions, run_emulation
    from tests.pipeline.refine.conftest import log_echoes

    src = Path(__file__).resolve().parents[3] / "sample_logs" / "radish" / "belgioioso-corrected.log.gz"
    log = tmp_path / "belgioioso.mcap"
    run_emulation(src, log, "mcap", options=EmulateOptions(sonar_model="ideal", drift=DriftModel(0.03, 0.8)))
    pr = Config().pose_refinement
    gap = round(pose_gap_limit_s(0, 1.0) * 1e9)  # the scans 1 s apart (the log has no time)
    track, echoes = log_echoes(log, pr.echo_reach_m, gap)
    cal = configured_calibration(*track, echoes, pr)
    assert math.degrees(cal.heading_bias) == pytest.approx(0.8, abs=0.01)
    assert cal.scale_error == pytest.approx(0.03, abs=0.005)
    never = configured_calibration(*track, echoes, pr, strong_gain=1e9)
    assert never.heading_bias == 0.0 and never.bias_rejected is not None
    rejected = never.bias_rejected
    assert rejected.sharper > STRONG_GAIN  # measured +19.4 %
    assert -MIN_GAIN < rejected.more_consistent < MIN_GAIN


@pytest.mark.parametrize("building", ["belgioioso", "fhw"])
def test_yaw_noise_alone_gets_no_heading_bias(tmp_path: Path, building: str) -> None:
    # Odometry with 0.01 rad/√rad of yaw noise and no bias. Belgioioso: the consistency scan
    # found -1.65°/m (a full turn over the run; 1.4 % less sharp, 3.5 % more consistent:
    # F1 0.257 -> 0.046). FHW: the sharpest bias a spike beside 0, the most consistent near
    # it +0.03°/m, 3.2 % less sharp than none (0.188 -> 0.138). Neither passes the gate now.
    # With the bias steps uncapped (at most 4° over the run however long), FHW's finer grid
    # finds a bias of -0.0105°/m, a hundredth of those failures (the CLI's emulation of the
    # same drift: F1 0.154 with the capped grid's, 0.188 with it, 0.166 unrefined).
    from pipeline.drift import DriftModel
    from pipeline.refine.refine import configured_calibration
    from pipeline.stages.pose_sync import pose_gap_limit_s
    from pipeline.tools.emulate import EmulateOptions, run_emulation
    from tests.pipeline.refine.conftest import log_echoes

    src = (Path(__file__).resolve().parents[3] / "sample_logs" / "radish"
           / f"{building}-corrected.log.gz")
    log = tmp_path / f"{building}.mcap"
    run_emulation(src, log, "mcap", options=EmulateOptions(sonar_model="ideal", drift=DriftModel(noise_yaw=0.01)))
    pr = Config().pose_refinement
    track, echoes = log_echoes(log, pr.echo_reach_m, round(pose_gap_limit_s(0, 1.0) * 1e9))
    cal = configured_calibration(*track, echoes, pr)
    assert abs(math.degrees(cal.heading_bias)) < 0.015  # measured 0 and 0.0105°/m
    assert cal.scale_error == 0.0


def _scripted_refinement(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                         answers: list[tuple[FixedPoint, ...]]) -> tuple[dict[str, Any], list[float]]:
    """Örebro emulated with 3 % and 0.8°/m of drift (make compare's row), refined with the
    surfaces' scale estimates replaced by ``answers`` in turn (each call of ``fixed_points`` takes the
    next: near, or near and far), and the heading bias found at a scale other than 0 moved by
    0.01°/m (the bias found at k = 0 absorbs part of the scale); the refinement's metrics
    and the heading bias (°/m per reported metre) each estimate was asked under. The
    offset-only patch model alone (``calibration_scale_tilt = "off"``): these are its rules."""
    import pipeline.refine.calibration as calibration
    import pipeline.refine.refine as rf
    import pipeline.refine.surfaces as surfaces
    from pipeline.drift import DriftModel
    from pipeline.run import run
    from pipeline.tools.emulate import EmulateOptions, run_emulation

    asked: list[float] = []

    def scripted(estimators: list[SurfaceScale]) -> list[FixedPoint]:
        asked.append(math.degrees(estimators[0].bias))
        return list(answers[len(asked) - 1][:len(estimators)])

    heading_bias, most_consistent = calibration._heading_bias, calibration._most_consistent

    def moved_heading_bias(sharp: Any, consistent: Any, k: float, *args: Any) -> Any:
        b, rejected = heading_bias(sharp, consistent, k, *args)
        return (b + math.radians(0.01) if k and b else b), rejected

    def moved_most_consistent(consistent: Any, k: float, *args: Any) -> float:
        return most_consistent(consistent, k, *args) + (math.radians(0.01) if k else 0.0)

    monkeypatch.setattr(surfaces, "fixed_points", scripted)  # SurfaceScale.fixed_point's
    monkeypatch.setattr(calibration, "fixed_points", scripted)
    monkeypatch.setattr(calibration, "_heading_bias", moved_heading_bias)
    monkeypatch.setattr(calibration, "_most_consistent", moved_most_consistent)
    tmp_path.mkdir(parents=True, exist_ok=True)
    src = Path(__file__).resolve().parents[3] / "sample_logs" / "radish" / "orebro-corrected.log.gz"
    log = tmp_path / "orebro.mcap"
    run_emulation(src, log, "mcap", options=EmulateOptions(sonar_model="ideal", drift=DriftModel(0.03, 0.8)))
    cfg = Config()
    gates = rf.calibration_gates()
    monkeypatch.setattr(rf, "calibration_gates", lambda: {**gates, "tilt": "off"})
    refine = Config(pose_refinement=dataclasses.replace(cfg.pose_refinement, enabled=True))
    found = run(log, tmp_path / "out", refine, force=True).metrics.pose_refinement
    assert found is not None
    return found, asked


def test_the_gate_judges_the_scale_under_the_bias_found_at_that_scale(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The first scale, under the bias found at k = 0 (which absorbs part of the scale),
    # stands under 3 errors from 0 (z 2.7 with the estimator's 0.5 % in quadrature); the
    # bias is found again at that scale, and under it the scale stands clear (z 3.7): it
    # is applied. (Measured so on the Intel lab with +1.5 % and +0.4°/m in the thirteenth
    # session: z 2.95, then 3.01, refined F1 0.69 → 0.99 of true poses.)
    first, second = FixedPoint(0.02, 0.3, (), 0.0055), FixedPoint(0.018, 0.3, (), 0.002)
    found, asked = _scripted_refinement(tmp_path, monkeypatch, [(first, first), (second,)])
    assert len(asked) == 2 and asked[1] != asked[0]  # asked again, under another bias
    assert found["search_scale_error"] == pytest.approx(0.018)
    assert found["scale_z"] == pytest.approx(0.018 / math.hypot(0.002, 0.005))


def test_near_and_far_echoes_that_disagree_are_asked_again_under_the_far_scales_bias(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Near and far echoes disagree under the bias of k = 0, the far ones the more precise
    # without establishing a scale by themselves (Örebro with 3 % and 0.8°/m in the
    # thirteenth session: +2.4 ± 1.8 % / +4.2 ± 1.6 %): the bias is found again at the far
    # scale and both asked again under it; there they agree, and the far echoes' scale,
    # 3 errors clear, is applied.
    near, far = FixedPoint(0.01, 0.4, (), 0.02), FixedPoint(0.045, 0.5, (), 0.016)
    near2, far2 = FixedPoint(0.029, 0.4, (), 0.008), FixedPoint(0.03, 0.5, (), 0.007)
    found, asked = _scripted_refinement(tmp_path, monkeypatch, [(near, far), (near2, far2)])
    assert len(asked) == 2 and asked[1] != asked[0]
    assert found["search_scale_error"] == pytest.approx(0.03)
    assert found["scale_far_echoes"] is True
    assert "scale_far_estimate" not in found  # no dispute left

    # Where they still disagree, nothing is applied and the dispute is reported.
    found, _ = _scripted_refinement(tmp_path / "again", monkeypatch, [(near, far), (near, far)])
    assert found["search_scale_error"] == 0.0
    assert found["scale_far_estimate"] == pytest.approx(0.045)


def test_front_sonars_near_scale_misled_in_shelving_gives_way_to_the_far_one(
        tmp_path: Path) -> None:
    # A warehouse's shelving (sample_logs/worlds/warehouse.toml) seen by the Pioneer's 8
    # front sonars, drifted by 3 % and 0.8°/m (drift_variety's row): the near echoes'
    # scale leans to the search's edge (+5.0 ± 0.6 %), the far echoes' (+3.4 ± 0.3 %)
    # disagrees and establishes one: it is applied (refined F1 0.70 → 0.98 of true poses).
    from pipeline.run import run
    from pipeline.tools.simulate import run_simulation

    world = Path(__file__).resolve().parents[3] / "sample_logs" / "worlds" / "warehouse.toml"
    log = tmp_path / "warehouse.mcap"
    run_simulation(world, log, "mcap", options=SimOptions(sonar_model="ideal",
        seed=1, speed=0.5, ring_rate_hz=5.0, mounts=PRESETS["pioneer-p3dx-front"],
        drift_scale=0.03, drift_heading_bias_deg_per_m=0.8))
    cfg = Config()
    refine = Config(pose_refinement=dataclasses.replace(cfg.pose_refinement, enabled=True))
    found = run(log, tmp_path / "out", refine, force=True).metrics.pose_refinement
    assert found is not None
    assert found["scale_far_echoes"] is True and "scale_far_estimate" not in found  # no dispute
    assert found["search_scale_error"] == pytest.approx(0.03, abs=0.006)  # measured 0.034 (was 0.050)
    assert found["search_heading_bias_deg_per_m"] == pytest.approx(0.8, abs=0.02)  # measured 0.804


def test_the_configured_calibration_takes_the_near_and_far_echoes_the_config_names(
        sample_echoes: SampleEchoes) -> None:
    import dataclasses

    from pipeline.config import Config
    from pipeline.refine.calibration import calibrate
    from pipeline.refine.refine import calibration_gates, configured_calibration

    cfg = Config().pose_refinement
    track, echoes = sample_echoes("office", 5.0)
    near = echoes.take(np.flatnonzero(echoes.range_m <= cfg.max_echo_range_m))
    far = echoes.take(np.flatnonzero(echoes.range_m <= cfg.calibration_far_range_m))
    kwargs = dict(max_scale=cfg.calibration_max_scale,
                  max_bias=math.radians(cfg.calibration_max_bias_deg_per_m),
                  res=cfg.field_resolution_m, sigma=cfg.field_sigma_m,
                  **calibration_gates())
    assert len(near) < len(far) < len(echoes) + 1
    assert configured_calibration(*track, echoes, cfg) == calibrate(*track, near, far_echoes=far,
                                                                    **kwargs)
    # a far range no longer than the near one: the near echoes alone
    short = dataclasses.replace(cfg, calibration_far_range_m=cfg.max_echo_range_m)
    assert configured_calibration(*track, echoes, short) == calibrate(*track, near, **kwargs)
