"""Wall lines from the echoes' tangents (pipeline.mapper.wall_lines): hand-made walls."""

from __future__ import annotations

import math

import numpy as np

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
