"""The reference map of an emulated log: the laser's own occupancy grid, every beam
ray-cast from the laser pose (log-odds, nav2 trinary when written).

A cell is a wall only when the laser hits it consistently: at least ``min_hits`` (2) hits,
and hits more than ``min_hit_share`` (0.25) of the beams that reach it (hits + passes):
GMapping's occupancy rule (hits / visits over its ``occ_thresh``, 0.25). One stray hit from
range noise or pose jitter no longer thickens a wall. Cells that fail the rule but whose
log-odds lean occupied are unknown, not free. The measured effect on wall thickness is in
docs/EVALUATION.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formats.arrays import F32, F64, I32, I64
from formats.errors import ConfigError, InputError
from formats.laser_log import LaserLog
from formats.map_types import GridSpec
from pipeline.tools.emulate.emulation import CHUNK_CELLS


@dataclass(frozen=True)
class LaserMapOptions:
    """Ray casting of the reference laser map (m; log-odds per observation)."""

    resolution: float = 0.05
    margin: float = 0.5  # around the poses and endpoints
    max_free_range: float = 30.0  # no-return beams clear free space up to this, m
    p_occ: float = 0.9  # inverse sensor model at the endpoint cell
    p_free: float = 0.4  # ... and along the beam
    max_cells: int = 50_000_000
    min_hits: int = 2  # a wall cell is hit at least this often ...
    min_hit_share: float = 0.25  # ... and by more than this share of the beams reaching it


@dataclass(frozen=True)
class LaserMap:
    """The laser occupancy grid: probability (NaN unknown), per-cell hit and pass counts."""

    probability: F32
    grid: GridSpec
    hits: I32
    passes: I32


def laser_occupancy_map(log: LaserLog, options: LaserMapOptions | None = None) -> LaserMap:
    """Log-odds map of every beam cast from the laser pose (vectorised sampling at half a
    cell): each beam counts once per cell it crosses as free, its endpoint cell (a return
    below the laser max) as occupied; L = hits·logit(p_occ) + passes·logit(p_free), summed
    without clamping so the map does not depend on the scan order. Cells that are not walls
    by the module's rule (consistent hits) but lean occupied get p = 0.5 (unknown)."""
    opt = options if options is not None else LaserMapOptions()
    res = opt.resolution
    if not res > 0:
        raise ConfigError(f"laser map resolution must be > 0, got {res!r}")
    lx, ly, lyaw = log.laser_poses()
    valid = log.valid_returns()
    th = lyaw[:, None] + log.angles
    cos, sin = np.cos(th), np.sin(th)
    r = log.ranges
    hx = (lx[:, None] + r * cos)[valid]
    hy = (ly[:, None] + r * sin)[valid]
    xs = np.concatenate([lx, hx])
    ys = np.concatenate([ly, hy])
    grid = GridSpec.covering(
        float(xs.min()) - opt.margin,
        float(ys.min()) - opt.margin,
        float(xs.max()) + opt.margin,
        float(ys.max()) + opt.margin,
        res,
    )
    if grid.width * grid.height > opt.max_cells:
        raise InputError(
            f"laser map would have {grid.width}×{grid.height} cells (> {opt.max_cells}); "
            "use a coarser resolution"
        )
    n_cells = grid.width * grid.height

    def cell_of(x: F64, y: F64) -> I64:
        c = np.floor((x - grid.origin_x) / res).astype(np.int64)
        rr = np.floor((y - grid.origin_y) / res).astype(np.int64)
        inside = (c >= 0) & (c < grid.width) & (rr >= 0) & (rr < grid.height)
        return np.where(inside, rr * grid.width + c, -1)

    hit_cell = cell_of(hx, hy)
    hits = np.bincount(hit_cell[hit_cell >= 0], minlength=n_cells)

    # Free length per beam: to the echo, or up to the cap for no-return beams.
    with np.errstate(invalid="ignore"):
        no_return = (r >= log.range_max[:, None]) | np.isposinf(r)
    cap = np.minimum(log.range_max, opt.max_free_range)[:, None]
    length = np.where(valid, r, np.where(no_return, cap, 0.0))
    end_cell = np.full(r.shape, -1, np.int64)
    end_cell[valid] = hit_cell
    beams = np.nonzero(length.reshape(-1) > 0)[0]
    length_b = length.reshape(-1)[beams]
    step = 0.5 * res
    count = np.ceil(length_b / step).astype(np.int64)
    scan_b = beams // r.shape[1]
    ox, oy = lx[scan_b], ly[scan_b]
    cb, sb = cos.reshape(-1)[beams], sin.reshape(-1)[beams]
    endb = end_cell.reshape(-1)[beams]
    passes = np.zeros(n_cells, np.int64)
    bounds = np.concatenate([[0], np.cumsum(count)])
    cuts = np.searchsorted(bounds, np.arange(0, int(bounds[-1]), CHUNK_CELLS), side="right") - 1
    cuts = np.unique(np.concatenate([cuts, [beams.shape[0]]]))
    for a, b in zip(cuts[:-1].tolist(), cuts[1:].tolist(), strict=True):
        n = count[a:b]
        rep = np.repeat(np.arange(a, b), n)
        k = np.arange(int(n.sum())) - np.repeat(bounds[a:b] - bounds[a], n)
        s = k * step
        cell = cell_of(ox[rep] + s * cb[rep], oy[rep] + s * sb[rep])
        # A beam crosses each cell in one run of samples: count the first of each run.
        first = np.ones(cell.shape, bool)
        first[1:] = (cell[1:] != cell[:-1]) | (rep[1:] != rep[:-1])
        use = first & (cell >= 0) & (cell != endb[rep])
        passes += np.bincount(cell[use], minlength=n_cells)
    l_occ = math.log(opt.p_occ / (1 - opt.p_occ))
    l_free = math.log(opt.p_free / (1 - opt.p_free))
    logodds = hits * l_occ + passes * l_free
    with np.errstate(over="ignore"):  # a cell passed thousands of times: exp → inf, prob 0
        prob = 1.0 / (1.0 + np.exp(-logodds))
    prob[(hits + passes) == 0] = np.nan
    wall = (hits >= opt.min_hits) & (hits > opt.min_hit_share * (hits + passes))
    prob[~wall & (prob > 0.5)] = 0.5  # leans occupied without consistent hits: unknown
    shape = grid.shape
    return LaserMap(
        prob.reshape(shape).astype(np.float32),
        grid,
        hits.reshape(shape).astype(np.int32),
        passes.reshape(shape).astype(np.int32),
    )
