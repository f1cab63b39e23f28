"""The scores the calibration searches (pipeline/refine/scores.py): sharpness and echo
consistency of a simulated room's echoes under candidate calibrations, their compiled
kernels against the numpy references, the odometry re-integrated at the echoes, thinning
and memory."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formats.angles import wrap_angle
from formats.presets import PRESETS
from pipeline.drift import DriftModel
from pipeline.refine import Echoes
from pipeline.refine.scores import BinnedSharpness, Consistency, Placed, Sharpness
from pipeline.tools.simulate import SimOptions, simulate, write_simulation
from pipeline.tools.simulate.world import world_from_dict
from tests.pipeline.refine.conftest import log_echoes

Run = tuple[tuple[np.ndarray, ...], Echoes]  # the pose track (t, x, y, yaw), its echoes

WORLD = {
    "polygon": [{"points": [[0, 0], [10, 0], [10, 6], [0, 6]]}],
    "segment": [{"from": [3, 0], "to": [3, 2.5]}, {"from": [6, 6], "to": [6, 3.5]},
                {"from": [7.5, 1.5], "to": [8.5, 1.5]}, {"from": [4.5, 3], "to": [4.5, 4]}],
}
WAYPOINTS = [[1.5, 1.5], [8.5, 3.0], [8.5, 4.8], [1.5, 4.8], [1.5, 1.5], [8.5, 3.0]]


@pytest.fixture(scope="module")
def true_run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    """A room driven by a Pioneer's 16 sonars: its true poses and echoes (whole cones)."""
    sim = simulate(world_from_dict(WORLD), WAYPOINTS,
                   SimOptions(sonar_model="ideal", seed=3, speed=0.4, ring_rate_hz=5.0,
                              mounts=PRESETS["pioneer-p3dx"]))
    log = tmp_path_factory.mktemp("cal") / "room.mcap"
    write_simulation(sim, log, "mcap")
    return log_echoes(log, 3.0, arc_fraction=1.0)


def scores(true_run: Run, kind: type, res: float) -> dict[float, float]:
    (t, x, y, yaw), echoes = true_run
    f = kind(t, x, y, yaw, echoes, res=res, sigma=0.1)
    return {k: f(k, 0.0) for k in (-0.04, 0.0, 0.04)}


def test_sharpness_prefers_a_shorter_scale_on_true_poses(true_run: Run) -> None:
    s = scores(true_run, Sharpness, 0.05)
    assert s[0.04] > s[0.0] > s[-0.04]  # shrinking the path packs the echoes: "sharper"


def test_consistency_peaks_at_the_true_scale(true_run: Run) -> None:
    c = scores(true_run, Consistency, 0.1)
    assert c[0.0] > c[0.04] and c[0.0] > c[-0.04]
    assert all(0.0 < v <= 1.0 for v in c.values())


def test_consistency_drops_under_a_heading_bias(true_run: Run) -> None:
    (t, x, y, yaw), echoes = true_run
    f = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
    assert f(0.0, 0.0) > f(0.0, math.radians(0.5)) + 0.02


@pytest.mark.parametrize(("k", "b_deg"), [(0.0, 0.0), (0.03, 0.8), (-0.05, -1.5)])
def test_the_compiled_consistency_gives_the_reference_score(true_run: Run,
                                                           k: float, b_deg: float) -> None:
    (t, x, y, yaw), echoes = true_run
    compiled = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
    reference = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1, reference=True)
    got, want = compiled(k, math.radians(b_deg)), reference(k, math.radians(b_deg))
    assert 0.3 < want < 1.0
    assert got == pytest.approx(want, rel=1e-12, abs=1e-12)


def test_the_echoes_are_more_consistent_on_true_poses_by_many_standard_errors(
        true_run: Run) -> None:
    (t, x, y, yaw), echoes = true_run
    f = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
    z = f.more_consistent_z((0.0, 0.0), (0.04, 0.0), 8.0)
    assert z > 3.0  # the true poses against a 4 % scale: clear
    assert f.more_consistent_z((0.04, 0.0), (0.0, 0.0), 8.0) == pytest.approx(-z)
    # per echo, the scores whose mean is the score (−1: too little evidence, not scored)
    each = f.per_echo(f.poses(0.04, 0.0))
    assert each.shape == (min(len(echoes), 2_500),)  # thinned as the score is
    assert each[each >= 0].mean() == pytest.approx(f(0.04, 0.0), abs=1e-9)
    # all the echoes within one cluster: no error to compare with
    assert math.isnan(f.more_consistent_z((0.0, 0.0), (0.04, 0.0), 1e6))
    assert math.isnan(f.more_consistent_z((0.0, 0.0), (0.0, 0.0), 8.0))  # no difference


def test_a_thinned_consistency_scores_the_whole_cones_of_the_echoes_it_keeps(
        true_run: Run) -> None:
    (t, x, y, yaw), echoes = true_run
    at_most = len(echoes) // 3
    thinned = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1, at_most=at_most)
    keep = np.linspace(0, len(echoes) - 1, at_most).round().astype(np.int64)
    bx, by = echoes.arc(1.0)  # the whole cone of every echo, then the kept rows
    assert thinned.bx.shape == (at_most, bx.shape[1])
    np.testing.assert_array_equal(thinned.bx, bx[keep])
    np.testing.assert_array_equal(thinned.by, by[keep])
    np.testing.assert_array_equal(thinned.sx, echoes.sx[keep])  # the arcs' sonars, in step
    alone = Consistency(t, x, y, yaw, echoes.take(keep), res=0.1, sigma=0.1)
    assert thinned(0.0, 0.0) == alone(0.0, 0.0)


def _kernel_score(arcs: list[tuple[np.ndarray, np.ndarray]], min_evidence: float) -> float:
    """The compiled consistency of arcs seen from sonars at the origin (10 cm cells and
    blur, free to 0.2 m short of each arc)."""
    from pipeline.refine.kernels import consistency_score

    wx, wy = np.vstack([a[0] for a in arcs]), np.vstack([a[1] for a in arcs])
    o = np.zeros(len(arcs))
    return float(consistency_score(wx, wy, o, o, np.arange(1, 31) * 0.1, 0.2, 0.1, 0.4,
                                   1.0, 4, min_evidence))


NEAR = (np.array([[1.0, 1.0, 1.0]]), np.array([[-0.3, 0.0, 0.3]]))  # an arc 1 m ahead
FAR = (np.array([[2.0, 2.0, 2.0]]), np.array([[-0.6, 0.0, 0.6]]))  # one 2 m ahead


def test_the_compiled_consistency_scores_an_echo_down_where_another_saw_free_space() -> None:
    from pipeline.refine.kernels import consistency_score

    # One echo: its arc holds only its own hits (blurred: < 2 per cell) and no free sample.
    assert _kernel_score([NEAR], 2.0) == 0.0  # nothing covered enough to score
    assert _kernel_score([NEAR], 0.1) > 0.9
    # A longer reading from the same sonar saw the near arc's cells free: it scores low.
    assert _kernel_score([NEAR, FAR], 0.1) < 0.8
    assert consistency_score(np.empty((0, 3)), np.empty((0, 3)), np.empty(0), np.empty(0),
                             np.arange(1, 31) * 0.1, 0.2, 0.1, 0.4, 1.0, 4,
                             0.1) == 0.0  # no echoes: nothing agrees


def test_the_consistency_moves_continuously_with_an_echo_inside_a_cell() -> None:
    # The far arc slid towards the near one in 5 mm steps (a twentieth of a cell) while
    # its rays keep their free samples: its cone covers the near arc more and more.
    # Counted into the nearest cell and read at a cell's value the score would stand
    # still and then jump at cell boundaries; shared over four cells and read at each
    # point's own position, every step moves it a little (measured 0.614 → 0.552).
    shifts = np.arange(0, 18) * 0.005
    scores = np.array([_kernel_score([NEAR, (FAR[0] - d, FAR[1])], 0.1) for d in shifts])
    steps = np.diff(scores)
    assert scores[0] - scores[-1] > 0.05  # the near arc ever less consistent
    assert steps.max() < 0  # every position inside the cell scores lower than the last
    assert steps.min() > -0.01  # and no jump


def test_the_compiled_binned_sharpness_counts_points_per_bin() -> None:
    from pipeline.refine.kernels import binned_sharpness

    # Bins of 0.2 m: three points share a bin, one lies far off, one just left of x = 0.
    # Unshifted grid: counts 3, 1, 1 → 11 / 25; grid shifted by half a bin: the one left
    # of 0 joins the three → 4, 1 → 17 / 25; the score is their mean.
    x = np.array([0.05, 0.05, 0.05, 1.05, -0.05])
    y = np.array([0.05, 0.05, 0.05, 1.05, 0.05])
    assert binned_sharpness(x, y, 0.2) == pytest.approx((11 / 25 + 17 / 25) / 2, abs=1e-15)
    assert binned_sharpness(x[:0], y[:0], 0.2) == 0.0
    # One point 1 km off: the box holds far more bins than 16 per point, so the bins are
    # hashed instead of counted in an array — the same counts, 3, 1, 1, 1 and 4, 1, 1.
    far_x, far_y = np.append(x, 1000.05), np.append(y, 1000.05)
    assert binned_sharpness(far_x, far_y, 0.2) == pytest.approx((12 / 36 + 18 / 36) / 2,
                                                                 abs=1e-15)


@pytest.mark.parametrize("b_deg", [0.0, 0.8, -2.5])
def test_the_compiled_binned_sharpness_is_the_reference_bit_for_bit(
        true_run: Run, b_deg: float) -> None:
    (t, x, y, yaw), echoes = true_run
    compiled = BinnedSharpness(t, x, y, yaw, echoes, sigma=0.1)
    reference = BinnedSharpness(t, x, y, yaw, echoes, sigma=0.1, reference=True)
    want = reference(0.0, math.radians(b_deg))
    assert 0.0 < want < 1.0
    assert compiled(0.0, math.radians(b_deg)) == want


@pytest.mark.parametrize("thinned", [None, 40])
def test_the_compiled_poses_are_drifted_many_to_a_nanometre(true_run: Run,
                                                            thinned: int | None) -> None:
    (t, x, y, yaw), echoes = true_run
    placed = Placed(t, x, y, yaw, echoes, thinned or len(echoes))
    at_odometry = np.column_stack([placed.x[placed.echo_at], placed.y[placed.echo_at],
                                   placed.yaw[placed.echo_at]])
    none = placed.poses_many(np.zeros(2), np.zeros(2))  # no calibration: nothing summed
    assert placed._segments is None and np.array_equal(none, np.stack([at_odometry] * 2))
    # no calibration first and last; two scales under one bias (summed once, scaled
    # apart); 30°/m turns a metre's segment by more than the Taylor sums are kept for
    ks = np.array([0.0, 0.03, -0.05, 0.0, 0.02, 0.0, -0.0])
    bs = np.radians([0.0, 0.8, -1.5, 2.5, 0.0, 30.0, -0.0])
    bs[4] = bs[3] * (1 + ks[4])  # the same bias per reported metre as the row before
    got = placed.poses_many(ks, bs)
    x_all, y_all, yaw_all = placed.motion.drifted_many(
        [DriftModel.removing(float(k), float(b)) for k, b in zip(ks, bs, strict=True)])
    i = placed.echo_at
    want = np.stack([x_all[:, i], y_all[:, i], yaw_all[:, i]], axis=-1)
    assert got.shape == (7, i.shape[0], 3) and i.shape[0] == (thinned or len(echoes))
    turn = np.abs(wrap_angle(got[..., 2] - want[..., 2]))
    assert np.abs(got[..., :2] - want[..., :2]).max() < 1e-9 and turn.max() < 1e-12
    for row in (0, 6):  # no calibration: the odometry's poses themselves
        assert np.array_equal(got[row], np.column_stack([placed.x[i], placed.y[i],
                                                         placed.yaw[i]]))
    assert np.abs(got[1] - got[0]).max() > 0.1  # 3 % and 0.8°/m move the poses
    assert np.abs(got[4, :, :2] - got[3, :, :2]).max() > 0.01  # the scale moves them apart
    assert np.abs(got[5] - got[0]).max() > 1.0  # 30°/m: the steps one by one


def test_the_scores_answer_a_calibration_asked_again_from_memory(
        true_run: Run, monkeypatch: pytest.MonkeyPatch) -> None:
    (t, x, y, yaw), echoes = true_run
    consistent = Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
    sharp = Sharpness(t, x, y, yaw, echoes, res=0.1, sigma=0.1)
    c, h = consistent(0.01, 0.002), sharp(0.01, 0.002)
    fresh = (Consistency(t, x, y, yaw, echoes, res=0.1, sigma=0.1)(0.01, 0.002),
             Sharpness(t, x, y, yaw, echoes, res=0.1, sigma=0.1)(0.01, 0.002))
    assert (c, h) == fresh  # the same value as a score that never saw it

    def recomputed(*_: object) -> float:
        raise AssertionError("asked again")

    monkeypatch.setattr(consistent, "_compiled", recomputed)
    monkeypatch.setattr(sharp, "arcs", recomputed)
    assert (consistent(0.01, 0.002), sharp(0.01, 0.002)) == (c, h)  # from memory
    with pytest.raises(AssertionError, match="asked again"):
        consistent(0.01, 0.003)  # a new calibration is computed


def test_the_consistency_scan_gives_the_scores_calls_give(true_run: Run) -> None:
    (t, x, y, yaw), echoes = true_run
    f = Consistency(t, x, y, yaw, echoes, res=0.2, sigma=0.2, at_most=300)
    bs = np.radians(np.linspace(-3.0, 3.0, 9))
    assert f.scan(0.01, bs, chunk=4) == [f(0.01, float(b)) for b in bs]
