"""Thrun's EM step of the research variant (benchmarks.research.em_forward): a wall seen
from two places, a phantom in front of it that other readings pass, a cell behind it."""

from __future__ import annotations

import math

import numpy as np

from benchmarks.research.em_forward import detection_bins, em_scores, m_step
from pipeline.mapper.grid_raster import cone_edges
from pipeline.mapper.kernels.specular import cell_lists

RES = 0.05
SHAPE = (120, 120)  # 6 m × 6 m from (0, 0)
HALF_FOV = math.radians(10.0)
BAND = 0.05
R_MAX = 5.0
P_BIN = detection_bins(np.array([0.9, 0.8, 0.7, 0.5, 0.3, 0.2, 0.1, 0.05, 0.05]), 0.4)
WALL_ROW = 80  # the wall: cells with 4.00 ≤ y < 4.05, normal (0, 1)
PHANTOM = (50, 50)  # a map cell in front of the wall, at (2.525, 2.525)
BEHIND = (90, 50)  # a map cell behind the wall


def the_map() -> np.ndarray:
    cells = np.zeros(SHAPE, dtype=bool)
    cells[WALL_ROW, 20:100] = True
    cells[PHANTOM] = True
    cells[BEHIND] = True
    return cells


VIS = np.linspace(1.0, 0.1, 10)  # a pass's weight per bin (the linear M-step)
LAST: dict[str, np.ndarray] = {}  # the last call's hits and free weights


def scores(readings: list[tuple[float, float, float]], cells: np.ndarray,
           rho: float = 0.05, silent_within: float | None = None,
           ) -> tuple[np.ndarray, np.ndarray, float, int]:
    """E-step of readings ``(ox, oy, echo range)`` facing +y (range 0: no echo); with
    ``silent_within`` the arc's cells more than that short of the echo that did not answer
    count as silent (``arcsilent=sigma``)."""
    ox, oy, d = (np.array(v, dtype=np.float64) for v in zip(*readings, strict=True))
    alpha = np.full(len(d), 0.5 * math.pi)
    half = np.full(len(d), HALF_FOV)
    r_max = np.full(len(d), R_MAX)
    outer = np.where(d > 0.0, d + BAND, R_MAX)
    s1, c1, s2, c2, up, down = cone_edges(alpha, half)
    cones = np.stack([ox, oy, outer, s1, c1, s2, c2], axis=1)
    up_down = np.stack([up, down], axis=1)
    r_inner = np.where(d > 0.0, d - BAND, np.inf)
    r_free = np.where(d > 0.0, d - 2 * BAND, R_MAX)
    nx = np.zeros(SHAPE, dtype=np.float32)
    ny = np.ones(SHAPE, dtype=np.float32)
    cons = np.ones(SHAPE, dtype=np.float32)
    idx, cols = cell_lists(cells)
    score = np.zeros(SHAPE)
    reached = np.zeros(SHAPE, dtype=bool)
    LAST["hits"], LAST["free"] = np.zeros(SHAPE), np.zeros(SHAPE)
    rand, echoes = em_scores(cones, up_down, r_inner, r_free, r_max, alpha, half, 0.0, 0.0,
                             RES, idx, cols, cells, nx, ny, cons, P_BIN, rho, silent_within is not None,
                             silent_within is not None, np.full(len(d), silent_within or 0.0),
                             score,
                             reached, VIS, 0.5, LAST["hits"], LAST["free"])
    return score, reached, rand, echoes


WALL_ECHO = 4.025 - 1.0  # a sonar at y = 1 m hears the wall's cells' centres head-on
# the wall from two places, the phantom once, and three readings that pass the phantom
READINGS = [(1.5, 1.0, WALL_ECHO), (3.5, 1.0, WALL_ECHO), (2.525, 1.0, 1.525),
            (2.525, 1.0, WALL_ECHO), (2.475, 0.8, WALL_ECHO + 0.2), (2.575, 0.9, WALL_ECHO + 0.1)]


def test_a_wall_seen_from_two_places_stays_and_a_passed_phantom_is_freed() -> None:
    cells = the_map()
    score, reached, _, echoes = scores(READINGS, cells)
    assert echoes == 6
    wall_seen = score[WALL_ROW, 25:35]  # the first reading's arc, near head-on
    assert (wall_seen > 0).all()
    # the phantom answered once (alone on its arc: e ≈ 1, + ln(p·width⁻¹/(ρ/r_max)))
    # and three readings passed it at head-on incidence (3·ln(1 − 0.9))
    answered = math.log(0.9 / (2 * BAND) / (0.05 / R_MAX))
    e = (0.9 / (2 * BAND)) / (0.9 / (2 * BAND) + 0.05 / R_MAX)
    assert math.isclose(score[PHANTOM], e * answered + 3 * math.log(0.1), rel_tol=1e-9)
    assert score[PHANTOM] < 0
    # the cell behind the wall is never reached: rays stop at the wall
    assert not reached[BEHIND] and score[BEHIND] == 0.0
    new = m_step(cells, score, reached, 0.0, False)
    assert not new[PHANTOM]
    assert new[WALL_ROW, 25:35].all()
    assert new[BEHIND]  # kept: no evidence
    assert not m_step(cells, score, reached, 0.0, True)[BEHIND]  # Thrun's prior: freed


def test_the_freed_phantom_no_longer_stops_the_rays_behind_it() -> None:
    cells = the_map()
    behind = (WALL_ROW, 50)  # the wall cell straight behind the phantom
    one = [(2.525, 1.0, 1.525)]  # the phantom's own reading
    _, reached, _, _ = scores(one, cells)
    assert reached[PHANTOM] and not reached[behind]
    cells[PHANTOM] = False
    _, reached, _, _ = scores([(2.525, 1.0, WALL_ECHO)], cells)
    assert reached[behind]


def test_echo_shared_among_arc_causes_and_the_random_cause() -> None:
    cells = the_map()
    one = [(3.0, 1.0, WALL_ECHO)]
    score, reached, rand, _ = scores(one, cells, rho=0.2)
    on_arc = reached[WALL_ROW]
    n = int(on_arc.sum())
    assert n >= 5  # the cone's width at 3 m, in cells
    lk = 0.9 / (2 * BAND)  # every arc cell is met nearly head-on (within 10°: bin 0)
    total = 0.2 / R_MAX + n * lk
    assert math.isclose(rand, (0.2 / R_MAX) / total, rel_tol=1e-9)
    expected = lk / total * math.log(lk / (0.2 / R_MAX))
    assert np.allclose(score[WALL_ROW][on_arc], expected)
    # the linear M-step's weights: e·n^(1 − dilution), no pass
    assert np.allclose(LAST["hits"][WALL_ROW][on_arc], lk / total * math.sqrt(n))
    assert not LAST["free"].any()
    # no echo: every reached cell closer than r_max passed, ln(1 − p) each
    none, passed, rand0, echoes0 = scores([(3.0, 1.0, 0.0)], cells)
    assert echoes0 == 0 and rand0 == 0.0
    seen = passed[WALL_ROW]
    assert seen.sum() >= 5 and not passed[BEHIND]
    assert np.allclose(none[WALL_ROW][seen], math.log(0.1))
    assert (none[WALL_ROW][~seen] == 0.0).all()
    assert np.allclose(LAST["free"][WALL_ROW][seen], 1.0) and not LAST["hits"].any()


def test_a_cell_freed_inside_a_band_keeps_its_state() -> None:
    band = np.zeros((7, 9), dtype=bool)
    band[2:5, 1:8] = True  # a wall band three cells thick
    score = np.ones(band.shape)
    score[3, 4] = -1.0  # its middle cell: more passes than echoes
    score[2, 1] = -1.0  # an end cell on its edge
    reached = band.copy()
    assert not m_step(band, score, reached, 0.0, False)[3, 4]  # a hole: thinned twice
    kept = m_step(band, score, reached, 0.0, False, keep_holes=True)
    assert kept[3, 4]  # enclosed: no ray from outside reaches it
    assert not kept[2, 1]  # the edge cell is freed
    assert kept.sum() == band.sum() - 1


def test_arc_cells_short_of_the_echo_that_did_not_answer_count_as_silent() -> None:
    cells = np.zeros(SHAPE, dtype=bool)
    cells[WALL_ROW, 20:100] = True
    d = WALL_ECHO + 0.03  # the wall's axis cells lie 0.03 m short of the echo
    plain, reached, _, _ = scores([(3.0, 1.0, d)], cells)
    silent, reached2, _, _ = scores([(3.0, 1.0, d)], cells, silent_within=0.02)
    assert np.array_equal(reached, reached2)
    cols = np.flatnonzero(reached[WALL_ROW])
    dist = np.hypot((cols + 0.5) * RES - 3.0, 4.025 - 1.0)
    short = dist < d - 0.02
    assert short.any() and (~short).any()  # the arc's ends lie beyond d − 0.02
    p = P_BIN[0]  # near head-on
    lk = p / (2 * BAND)
    e = lk / (0.05 / R_MAX + len(cols) * lk)
    diff = silent[WALL_ROW, cols] - plain[WALL_ROW, cols]
    assert np.allclose(diff[short], (1.0 - e) * math.log1p(-p))
    assert (diff[~short] == 0.0).all()
