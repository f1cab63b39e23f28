"""Wall lines from the echoes' tangents (pipeline.mapper.wall_lines): hand-made walls."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pipeline.mapper.wall_lines as wall_lines_module
from pipeline.mapper.kernels.lines import vote_tangents
from pipeline.mapper.types import GridSpec
from pipeline.mapper.wall_lines import LINE_BINS, empty_votes, near_lines, wall_lines

GRID = GridSpec(0.0, 0.0, 0.05, 120, 120)  # 6 m × 6 m
HALF_FOV = math.radians(15.0)
PSI = (8 + 0.5) * math.pi / LINE_BINS  # the wall's normal: 85°, a bin's centre


def ideal_echoes(ox: np.ndarray, oy: np.ndarray, d: float) -> np.ndarray:
    """Range of the ideal echo (the nearest point in the cone) from the wall
    ``x·cos PSI + y·sin PSI = d`` for sonars facing its normal: the perpendicular distance."""
    out: np.ndarray = d - (ox * math.cos(PSI) + oy * math.sin(PSI))
    return out


def votes_from(ox: np.ndarray, oy: np.ndarray, r: np.ndarray) -> np.ndarray:
    votes = empty_votes(GRID)
    alpha = np.full(len(ox), PSI)
    vote_tangents(ox, oy, alpha, np.full(len(ox), HALF_FOV), r, GRID.origin_x,
                  GRID.origin_y, GRID.resolution, votes)
    return votes


def test_a_wall_seen_along_a_path_is_a_line_with_its_normal() -> None:
    # the robot drives 3 m parallel to the wall, 2 m from it, one reading every 0.1 m
    t = np.arange(0.0, 3.0, 0.1)
    ox = 1.5 + t * -math.sin(PSI)
    oy = 1.0 + t * math.cos(PSI)
    d = 2.0 + 1.5 * math.cos(PSI) + 1.0 * math.sin(PSI)
    votes = votes_from(ox, oy, ideal_echoes(ox, oy, d))
    on, nx, ny = wall_lines(votes, GRID.resolution, 0.3)
    assert on.sum() > 30  # 3 m of wall: ~60 cells, the path's ends excepted
    rows, cols = np.nonzero(on)
    x, y = (cols + 0.5) * GRID.resolution, (rows + 0.5) * GRID.resolution
    offset = x * math.cos(PSI) + y * math.sin(PSI) - d
    assert np.abs(offset).max() <= 2 * GRID.resolution  # every line cell on the wall
    agree = np.abs(nx[on] * math.cos(PSI) + ny[on] * math.sin(PSI))
    assert agree.min() >= math.cos(math.radians(10.5))  # at worst the next bin
    assert np.mean(agree > 0.9999) >= 0.8  # mostly the wall's own bin
    near, nnx, nny = near_lines(on, nx, ny, 2.0)
    assert near.sum() > 2 * on.sum()
    assert np.abs(nnx[near] * math.cos(PSI) + nny[near] * math.sin(PSI)).min() >= math.cos(
        math.radians(10.5))


def test_a_single_pose_is_no_line() -> None:
    # the same reading repeated 20 times from one place: one arc, no agreement
    ox, oy = np.full(20, 3.0), np.full(20, 1.0)
    votes = votes_from(ox, oy, np.full(20, 2.0))
    assert votes.sum() > 0
    on, _, _ = wall_lines(votes, GRID.resolution, 0.3)
    assert not on.any()


def test_arcs_from_a_turn_in_place_are_no_line() -> None:
    # a sonar turning on the spot in a round room: tangents from one place in every bin
    alpha = np.linspace(0.0, 2 * math.pi, 72, endpoint=False)
    votes = empty_votes(GRID)
    vote_tangents(np.full(72, 3.0), np.full(72, 3.0), alpha, np.full(72, HALF_FOV),
                  np.full(72, 1.5), 0.0, 0.0, GRID.resolution, votes)
    on, _, _ = wall_lines(votes, GRID.resolution, 0.3)
    assert votes.sum() > 72 and not on.any()


def test_no_echo_no_votes() -> None:
    votes = votes_from(np.full(3, 3.0), np.full(3, 1.0), np.array([0.0, -1.0, np.nan]))
    assert votes.sum() == 0


def test_the_forward_method_uses_the_lines_in_pass_3_only() -> None:
    from pipeline.config import MapperConfig
    from pipeline.mapper import make_mapper
    from pipeline.mapper.forward import ForwardMapper
    from pipeline.mapper.synthetic import ring_scans, room_grid
    from pipeline.methods import Method

    scans = ring_scans(60)
    mapper = make_mapper(MapperConfig(method=Method.FORWARD, wall_line_half_length_m=0.3),
                         room_grid(0.05))
    assert isinstance(mapper, ForwardMapper)
    own = np.zeros(0, dtype=np.float32)
    for index in range(mapper.passes):
        mapper.begin_pass(index)
        if index == 3:  # the lines' cells are surfaces of known orientation
            assert mapper.votes.sum() > 0
            assert (mapper.consistency == 1.0).sum() > (own == 1.0).sum()
        if index == 4:  # the final attribution stops rays at the cells' own normals
            assert np.array_equal(mapper.consistency, own)
        mapper.integrate_many(scans)
        if index == 2:
            own = mapper.consistency.copy()
    assert mapper.snapshot().grid.shape == room_grid(0.05).shape


def test_a_cone_edge_on_a_bin_centre_votes_the_same_whatever_the_last_bits() -> None:
    # A sonar at 90° with a 30° beam: its cone edge 105° is bin 10's centre (10° bins). A
    # yaw read from a quaternion or from text differs in its last bits; the votes must not.
    def bins_voted(alpha: float) -> list[int]:
        votes = np.zeros((18, 40, 40), dtype=np.uint16)
        one = np.array([0.0])
        vote_tangents(one, one, np.array([alpha]), np.array([math.radians(15.0)]),
                      np.array([0.5]), -1.0, -1.0, 0.05, votes)
        return [b for b in range(18) if votes[b].any()]

    exact = bins_voted(math.pi / 2)
    assert exact == [7, 8, 9, 10]  # 75°, 85°, 95° and the edge 105°
    assert bins_voted(np.nextafter(math.pi / 2, 0.0)) == exact
    assert bins_voted(np.nextafter(math.pi / 2, 4.0)) == exact


def scattered_walls(shape: tuple[int, int], seed: int, axis_aligned: bool) -> np.ndarray:
    """Votes of 60 noisy straight walls (on the grid's axes when ``axis_aligned``: their
    votes lie exactly half a bin off the bins' lines) and stray single votes."""
    rng = np.random.default_rng(seed)
    votes = np.zeros((LINE_BINS, *shape), dtype=np.uint16)
    for _ in range(60):
        b = int(rng.integers(LINE_BINS))
        psi = rng.choice([0.0, math.pi / 2]) if axis_aligned else (b + 0.5) * math.pi / LINE_BINS
        r0, c0 = rng.integers(0, shape[0]), rng.integers(0, shape[1])
        for t in np.linspace(-20, 20, 25):
            r = round(r0 + t * math.cos(psi) + rng.normal(0, 0.4))
            c = round(c0 - t * math.sin(psi) + rng.normal(0, 0.4))
            if 0 <= r < shape[0] and 0 <= c < shape[1]:
                votes[b, r, c] += rng.integers(1, 4)
    votes += (rng.random(votes.shape) < 0.002).astype(np.uint16)
    return votes


@pytest.mark.parametrize("axis_aligned", [False, True])
def test_the_lines_do_not_depend_on_the_tiles(monkeypatch: pytest.MonkeyPatch,
                                              axis_aligned: bool) -> None:
    # the line test works tile by tile where votes are; one tile over the whole grid (the
    # way it was computed before) gives the same cells and normals, ties included
    votes = scattered_walls((300, 410), 1, axis_aligned)
    on, nx, ny = wall_lines(votes, 0.05, 0.3)
    monkeypatch.setattr(wall_lines_module, "TILE", 4096)
    on1, nx1, ny1 = wall_lines(votes, 0.05, 0.3)
    assert on.sum() > 1000
    assert np.array_equal(on, on1) and np.array_equal(nx, nx1) and np.array_equal(ny, ny1)


def test_two_votes_along_a_grid_axis_meet_the_tilt_bound_exactly_and_count() -> None:
    # a wall along x seen from five places, its votes in the bin of normals 80-90°: they
    # lie on one row, 5° off that bin's line (the bound), so rounding must not decide
    # whether they are a line
    b = LINE_BINS // 2 - 1
    votes = empty_votes(GridSpec(0.0, 0.0, 0.05, 40, 20))
    votes[b, 10, 12:29:4] = 1
    on, nx, ny = wall_lines(votes, 0.05, 0.3)
    assert on[10, 12:29].all() and not on[8].any() and not on[12].any()
    psi = (b + 0.5) * math.pi / LINE_BINS
    assert np.allclose(nx[10, 12:29], math.cos(psi)) and np.allclose(ny[10, 12:29], math.sin(psi))
