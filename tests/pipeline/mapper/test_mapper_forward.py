"""§11: the detection model measured on the log (hand-made walls through the compiled E-step),
the evidence a pass carries at each incidence, and the map of a room with an oblique wall
read by a specular and by an ideal sonar."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mapper_helpers import build_scan
from test_mapper_specular import _room

from pipeline.config import MapperConfig
from pipeline.mapper import ForwardMapper, make_mapper
from pipeline.mapper.forward import (
    INCIDENCE_BINS,
    evidence_table,
    fit_detection,
    fitted_detection,
    pass_evidence,
    reach_detection,
)
from pipeline.mapper.free_space import cone_table
from pipeline.mapper.kernels.forward import detection_counts
from pipeline.mapper.kernels.specular import cell_lists
from pipeline.mapper.specular import TABLE_STEP, visibility_table
from pipeline.mapper.synthetic import room_grid
from pipeline.methods import Method

RES = 0.05


def _tallies(occ: np.ndarray, normal_deg: float,
             readings: list[tuple[float, float, float, float]],
             r_max: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """The E-step's tallies for readings ``(ox, oy, alpha, range)`` (range ``r_max``: no
    echo) on a grid of surfaces ``occ`` (origin 0, 0) whose normals all point along
    ``normal_deg`` with full consistency: (answered, passed) per reading and incidence bin,
    and (on the arc, passed) per reached surface cell and bin."""
    ox, oy, alpha, d = (np.array(v, dtype=np.float64) for v in zip(*readings, strict=True))
    scan = build_scan(d, alpha, ox, oy, fov=math.radians(10.0), max_range=r_max)
    echo = d < r_max - 0.01
    band = 0.05
    free_r = np.where(echo, d - 0.05, r_max - 0.01)
    outer = np.where(echo, d + band, free_r)
    rows, cones, up_down = cone_table(scan, outer)
    r_inner = np.where(echo, d - band, np.inf)[rows]
    shape = occ.shape
    occ_index, occ_cols = cell_lists(occ)
    nx = np.full(shape, math.cos(math.radians(normal_deg)), np.float32)
    ny = np.full(shape, math.sin(math.radians(normal_deg)), np.float32)
    stats = np.zeros((2, INCIDENCE_BINS + 1))
    reaches = np.zeros((2, INCIDENCE_BINS))
    detection_counts(cones, up_down, r_inner, free_r[rows], scan.alpha[rows],
                     0.5 * scan.fov[rows], 0.0, 0.0, RES, occ_index, occ_cols, nx, ny,
                     np.ones(shape, np.float32), stats, reaches)
    return stats, reaches


def _counts(occ: np.ndarray, normal_deg: float, readings: list[tuple[float, float, float, float]],
            r_max: float = 5.0) -> np.ndarray:
    """The E-step's (answered, passed) counts per reading and incidence bin (:func:`_tallies`)."""
    return _tallies(occ, normal_deg, readings, r_max)[0]


def _wall_grid(*cols: int) -> np.ndarray:
    """A 120 × 120 grid (6 m) with vertical walls (normal along x) at the given columns."""
    occ = np.zeros((120, 120), bool)
    for c in cols:
        occ[:, c] = True
    return occ


def test_a_wall_heard_head_on_is_answered_in_the_first_bin() -> None:
    wall = 60  # x = 3.025 m
    stats = _counts(_wall_grid(wall), 0.0, [(1.0, 3.0, 0.0, 2.025)])
    assert stats[0, 0] >= 1 and stats[0].sum() == stats[0, 0]
    assert stats[1].sum() == 0


def test_a_phantom_behind_a_wall_is_explained_away() -> None:
    # The echo lands on a surface 1 m behind the wall: the wall stops every ray of the cone,
    # so the phantom is never reached; the reading passed the wall head-on without answer.
    stats = _counts(_wall_grid(60, 80), 0.0, [(1.0, 3.0, 0.0, 3.025)])
    assert stats[0].sum() == 0
    assert stats[1, 0] >= 1 and stats[1].sum() == stats[1, 0]


def test_a_wall_passed_obliquely_counts_in_its_incidence_bin() -> None:
    # A reading with no echo meets the wall 55-65° off its normal (its ±5° cone): it passed
    # the wall there, in the 50-60° or 60-70° bin, and answered nowhere.
    stats = _counts(_wall_grid(60), 0.0, [(1.0, 1.0, math.radians(60.0), 5.0)])
    assert stats[0].sum() == 0
    assert stats[1, 5:7].sum() >= 1 and stats[1].sum() == stats[1, 5:7].sum()


def test_every_reached_surface_cell_is_tallied_once_in_its_bin() -> None:
    wall = 60  # x = 3.025 m
    # Head-on: the wall's cells in the 10° cone (about 4 cells tall at 2 m) are on the arc.
    _, head_on = _tallies(_wall_grid(wall), 0.0, [(1.0, 3.0, 0.0, 2.025)])
    assert head_on[0, 0] >= 3 and head_on[0].sum() == head_on[0, 0]
    assert head_on[1].sum() == 0
    # The echo comes from 1 m behind the wall: every reached wall cell was passed head-on,
    # the surface behind it is never reached.
    _, behind = _tallies(_wall_grid(60, 80), 0.0, [(1.0, 3.0, 0.0, 3.025)])
    assert behind[0].sum() == 0
    assert behind[1, 0] >= 3 and behind[1].sum() == behind[1, 0]
    # No echo at 55-65° off the wall's normal: the reached cells were passed there (a cell
    # met obliquely shades the next one along the wall: the first ones are reached).
    _, oblique = _tallies(_wall_grid(wall), 0.0, [(1.0, 1.0, math.radians(60.0), 5.0)])
    assert oblique[0].sum() == 0
    assert oblique[1, 5:7].sum() >= 1 and oblique[1].sum() == oblique[1, 5:7].sum()


def test_the_detection_of_reached_surface_cells() -> None:
    reaches = np.zeros((2, INCIDENCE_BINS))
    reaches[0, 0], reaches[1, 0] = 18, 0
    reaches[0, 4], reaches[1, 4] = 3, 7
    p = reach_detection(reaches)
    assert p[0] == pytest.approx(19 / 20)
    # No data in bins 1-3 nor 5-8 (the prior's even odds, 0.5): a share may not rise with
    # incidence, so bins 5-8 pool with bin 4 (4/12): (4 + 4·1) / (12 + 4·2).
    assert p[1:4] == pytest.approx(np.full(3, 0.5))
    assert p[4:] == pytest.approx(np.full(5, 8 / 20))
    assert np.all(np.diff(p) <= 0)
    # The pooling weighs bins by their counts: a rising bin with 2 reaches barely moves a
    # bin with 200 before it.
    reaches = np.zeros((2, INCIDENCE_BINS))
    reaches[:, 0] = 150, 50
    reaches[:, 1] = 2, 0
    p = reach_detection(reaches)
    assert p[0] == p[1] == pytest.approx((151 + 3) / (202 + 4))


def test_a_pass_counts_fully_where_surfaces_answer_as_often_as_head_on() -> None:
    # No specular loss: every bin answers as head-on, every pass is full evidence (§9).
    assert np.array_equal(pass_evidence(np.full(INCIDENCE_BINS, 0.9)), np.ones(INCIDENCE_BINS))
    # A mirror: bins that never answer carry no evidence; in between, the log-likelihood
    # ratio of a pass against a surface, relative to a head-on pass.
    p = np.array([0.9, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.95])
    w = pass_evidence(p)
    assert w[1] == pytest.approx(math.log(0.5) / math.log(0.1))
    assert np.array_equal(w[2:8], np.zeros(6))
    assert w[8] == 1.0  # answers more often than head-on: clipped to a full pass


def test_the_evidence_table_runs_through_the_bins_centres() -> None:
    w = np.linspace(1.0, 0.2, INCIDENCE_BINS)
    table = evidence_table(w)
    centres = (np.arange(INCIDENCE_BINS) + 0.5) * (0.5 * math.pi / INCIDENCE_BINS)
    at = np.round(centres / TABLE_STEP).astype(int)
    assert np.allclose(table[at], w)
    assert table[0] == 1.0 and table[-1] == pytest.approx(0.2)  # flat beyond the centres
    assert np.all(np.diff(table) <= 1e-12)


def test_the_smoothed_share_answered() -> None:
    stats = np.zeros((2, INCIDENCE_BINS + 1))
    stats[0, 0], stats[1, 0] = 8, 0
    stats[0, 5], stats[1, 5] = 1, 9
    p_d = fitted_detection(stats)
    assert p_d[0] == pytest.approx(0.9) and p_d[5] == pytest.approx(2 / 12)
    assert p_d[8] == pytest.approx(0.5)  # no data: the smoothing's even odds


@pytest.mark.parametrize(("p0", "median", "spread", "floor"),
                         [(0.8, 10.0, 0.7, 0.15), (1.0, 40.0, 0.35, 0.0)])
def test_the_fit_recovers_the_detection_model(p0: float, median: float, spread: float,
                                              floor: float) -> None:
    # Exact expected counts of 10 000 reaches per bin drawn from the model.
    centres = (np.arange(INCIDENCE_BINS) + 0.5) * (90.0 / INCIDENCE_BINS)
    vis = visibility_table(median, spread)[np.round(np.radians(centres) / TABLE_STEP)
                                           .astype(int)]
    share = floor + (1.0 - floor) * p0 * vis
    stats = np.zeros((2, INCIDENCE_BINS + 1))
    stats[0, :INCIDENCE_BINS] = 10_000 * share
    stats[1, :INCIDENCE_BINS] = 10_000 * (1.0 - share)
    fp0, fmedian, fspread, ffloor = fit_detection(stats)
    assert ffloor == pytest.approx(floor, abs=0.02)
    # The curve §10's passes get: the specular part only, the coincidences left out; on the
    # bins it is the model's within a grid step (head-on rate and median trade off inside
    # the first bin).
    table = fp0 * visibility_table(fmedian, fspread)
    at = np.round(np.radians(centres) / TABLE_STEP).astype(int)
    assert np.abs(table[at] - p0 * vis).max() < 0.04
    assert table[0] == pytest.approx(fp0)


def _mapped(critical_deg: float | None) -> ForwardMapper:
    m = make_mapper(MapperConfig(method=Method.FORWARD), room_grid())
    assert isinstance(m, ForwardMapper)
    from specular_room import specular_scans

    scans = specular_scans(300, critical_deg)
    for index in range(m.passes):
        m.begin_pass(index)
        m.integrate_many(scans)
    return m


def _fitted(critical_deg: float | None) -> np.ndarray:
    return _mapped(critical_deg).p_d


def test_the_pass_evidence_is_measured_not_assumed() -> None:
    specular, ideal = _mapped(20.0), _mapped(None)
    at = np.round(np.radians([40.0, 60.0, 80.0]) / TABLE_STEP).astype(int)
    # Walls that answer only within 20° of their normal: a pass 40-80° off it says almost
    # nothing against them (measured 0.003-0.08), and a ray stops at one met there. The
    # ideal sonar's walls answer at every incidence: a pass there is most of a head-on
    # pass's evidence (measured 0.80, 0.64, 0.45) and no ray stops at a wall met up to 60°.
    assert specular.table[at].max() < 0.1
    assert ideal.table[at[:2]].min() > 0.6 and ideal.table[at[2]] > 0.4
    assert specular.table[0] == ideal.table[0] == 1.0
    assert np.all(np.diff(ideal.table) <= 1e-12)  # does not rise with incidence
    assert np.any(specular.consistency[specular.surfaces] * (1.0 - specular.table[at[0]]) > 0.5)
    assert not np.any(ideal.consistency[ideal.surfaces] * (1.0 - ideal.table[at[1]]) > 0.5)


def test_the_curve_tells_a_specular_sonar_from_an_ideal_one() -> None:
    specular, ideal = _fitted(20.0), _fitted(None)
    oblique = slice(3, 8)  # 30-80°
    # Measured (walls answer within 20° of their normal, or always): 0.83 and 0.91 head-on,
    # 0.51 and 0.89 at 10-20°; 30-80°: 0.005-0.07 against 0.72-0.90.
    assert specular[0] > 0.75 and ideal[0] > 0.85
    assert specular[oblique].max() < 0.15
    assert ideal[oblique].min() > 0.6


def test_the_room_with_the_measured_unknown_rate() -> None:
    ours, plain = _room("forward", 20.0), _room("attribution", 20.0)
    # Measured: oblique wall 0.57 vs 0.33, precision 0.85 vs 0.74, behind the wall 13 vs 26.
    assert ours["oblique_recall"] > plain["oblique_recall"] + 0.2
    assert ours["precision"] > plain["precision"] + 0.05
    assert ours["behind"] < plain["behind"]
    ideal, fixed = _room("forward", None), _room("specular", None)
    # Measured on the ideal sonar: precision 0.81 vs §10's 0.72 (its v̄ = 0.29 discounts
    # the free evidence of every cell of unknown orientation; this sonar's answer when met).
    assert ideal["precision"] > fixed["precision"] + 0.05
    assert ideal["recall"] >= fixed["recall"] - 0.03


def test_the_default_is_five_passes_and_checks_them() -> None:
    m = make_mapper(MapperConfig(), room_grid(0.1))
    assert isinstance(m, ForwardMapper) and m.passes == 5
    with pytest.raises(ValueError, match="passes 0 to 4"):
        m.begin_pass(5)
