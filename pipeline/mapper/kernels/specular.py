"""Compiled per-reading loop of the specular method (ALGORITHM.md §10).

One reading's cone out to ``cones[i, 2]`` (the far edge of its echo's arc, or ``r_max``
for a reading with no echo) is visited cell by cell (the cell rule of
:mod:`pipeline.mapper.kernels.cone`). A cell of the surfaces grid ``occ`` whose unit normal
``(nx, ny)`` is met by the ray at incidence θ answers with probability ``visible(θ)``
(:func:`visible`); where the cell's normal is consistent (``q = cons``) and
``q·(1 − visible(θ)) > ½`` the surface is silent to the ray and reflects it away, so the
ray stops: farther cells within the cell's angular width (bins uniform in the tangent of
the bearing off the axis) get no evidence from the reading. An unoccluded cell closer than ``r_free`` gets free evidence
``q·visible(θ) + (1 − q)·v_unknown`` (``q`` = the consistency of its pooled normal,
``v_unknown`` = visibility of a surface of unknown orientation); arc cells
(``r_inner ≤ dist``) are counted (``attribute = False``) or, with ``attribute``, are an
echo's candidates unless ``free_in > ratio·arcs_in`` (as §9); the echo is spread over its
``n`` candidates, ``1/n**dilution`` each. In ``attribute`` mode every arc cell also adds
its bearing φ from the sonar as a doubled angle (``cos 2φ, sin 2φ``: an axial direction)
to ``arc_c, arc_s``, from which the normals are pooled.

Loops run in reading order and add in that order, so results are deterministic.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from pipeline.mapper.kernels.attribution import reach_cells, span_buffers, spread_echo
from pipeline.mapper.kernels.cone import (
    cone_row_spans,
    cone_rows,
    edge_sector_spans,
    wrap_angle,
)
from pipeline.mapper.types import F32, F64, I32, I64, B

MAX_BINS = 2048  # angular bins of one cone's occlusion profile


@njit(cache=True, inline="always")
def visible(dx: float, dy: float, dist: float, nx: float, ny: float, table: F64) -> float:
    """The probability that a surface with unit normal ``(nx, ny)`` echoes the ray
    ``(dx, dy)`` of length ``dist``: ``table`` (the critical angle's survival function)
    sampled at cos θ = 0, 1/(n − 1), … 1, θ the incidence."""
    x = abs(dx * nx + dy * ny) / max(dist, 1e-12) * (table.shape[0] - 1)
    k = min(int(x), table.shape[0] - 2)
    f = x - k
    return table[k] * (1.0 - f) + table[k + 1] * f


@njit(cache=True, inline="always")
def shadow_bins(hb: float, r_out: float, res: float) -> int:
    """Angular bins of a cone's shadow profile: about one per cell across its far edge."""
    return min(MAX_BINS, math.ceil(2.0 * hb * r_out / res) + 1)


@njit(cache=True, inline="always")
def shade(stop: F64, nb: int, dist: float, t: float, t_edge: float, res: float,
          bin_w: float) -> None:
    """Stop at ``dist`` the rays of the bins (of ``nb``) that a cell at distance ``dist`` and
    tangent offset ``t`` off the axis covers: half a cell over the distance, in tangent units
    (stretched by ``1 + t²``); bins start at tangent ``-t_edge`` and are ``bin_w`` wide."""
    rel = t + t_edge
    hw = 0.5 * res / max(dist, res) * (1.0 + t * t)
    k0 = max(0, math.floor((rel - hw) / bin_w))
    k1 = min(nb - 1, math.floor((rel + hw) / bin_w))
    for kb in range(k0, k1 + 1):
        stop[kb] = min(stop[kb], dist)


@njit(cache=True, inline="always")
def cone_columns(ox: float, r_out: float, c1: float, c2: float, alpha: float, hb: float,
                 gx: float, res: float, width: int) -> tuple[int, int]:
    """The grid columns ``b0..b1`` (clipped) that hold every cell of a cone, with a cell of
    margin: its x extent is set by the edges' tips and the origin, and ``r_out`` where the
    wedge holds the +x or −x direction. A row span of the cone lies inside, so a row with
    no listed cell in ``b0..b1`` has none in its span either."""
    lo_x = min(0.0, min(r_out * c1, r_out * c2))
    hi_x = max(0.0, max(r_out * c1, r_out * c2))
    if abs(wrap_angle(-alpha)) <= hb:
        hi_x = r_out
    if abs(wrap_angle(math.pi - alpha)) <= hb:
        lo_x = -r_out
    b0 = min(max(math.floor(((ox + lo_x) - gx) / res - 0.5) - 1, 0), width - 1)
    b1 = min(max(math.ceil(((ox + hi_x) - gx) / res - 0.5) + 1, 0), width - 1)
    return b0, b1


@njit(cache=True, inline="always")
def listed_row_spans(cones: F64, up_down: B, i: int, alpha: float,
                     hb: float, occ_index: I32, gx: float, gy: float, res: float,
                     height: int, width: int, rows: I64, c0s: I64, c1s: I64) -> int:
    """edge_sector_spans' spans of cone ``i`` on only the rows that hold a listed cell
    (``occ_index``, CSR by row) in the cone's columns (:func:`cone_columns`), written to
    ``rows``, ``c0s``, ``c1s``; returns how many."""
    ox, oy, r_out = cones[i, 0], cones[i, 1], cones[i, 2]
    s1, c1, s2, c2 = cones[i, 3], cones[i, 4], cones[i, 5], cones[i, 6]
    r0, r1 = cone_rows(oy, r_out, s1, s2, up_down[i, 0], up_down[i, 1], gy, res, height)
    b0, b1 = cone_columns(ox, r_out, c1, c2, alpha, hb, gx, res, width)
    cone_row_spans(ox, oy, r_out, s1, c1, s2, c2, r0, r1, gx, gy, res, width, c0s, c1s)
    n = 0
    for row in range(r0, r1 + 1):  # the non-empty listed ones, in place
        a, b = c0s[row - r0], c1s[row - r0]
        if a <= b and occ_index[row, b1 + 1] != occ_index[row, b0]:
            rows[n] = row
            c0s[n] = a
            c1s[n] = b
            n += 1
    return n


@njit(cache=True, nogil=True)
def shadow_offsets(cones: F64, half_fov: F64, res: float) -> I64:
    """Where each reading's shadow profile starts in :func:`shadow_profiles`' ``stops``
    (and, last, their total length)."""
    out = np.zeros(cones.shape[0] + 1, dtype=np.int64)
    for i in range(cones.shape[0]):
        out[i + 1] = out[i] + shadow_bins(half_fov[i], cones[i, 2], res)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def shadow_profiles(
    cones: F64, up_down: B, r_inner: F64, alpha: F64, half_fov: F64, gx: float, gy: float,
    res: float, occ_index: I32, occ_cols: I32, nx: F32, ny: F32, cons: F32, table: F64,
    attribute: bool, lo: int, hi: int, offsets: I64, stops: F64, stopped: B, later: bool,
    nx2: F32, ny2: F32, cons2: F32, stopped2: B,
) -> int:
    """The shadows of the silent surfaces in the cones of readings ``lo:hi``: ``stopped[i]``
    whether a ray of reading ``i`` stops, and ``stops[offsets[i] + b]`` the distance where
    the rays of its angular bin ``b`` stop (bins uniform in the tangent of the bearing off
    the axis). With ``attribute`` the readings with no echo are left out (no arc). With
    ``later``, ``stopped2[i]``: whether a ray of reading ``i`` would stop at the same cells
    judged against the surfaces ``nx2, ny2, cons2`` (a later pass's), by the same test.
    Writes only these readings' entries, so calls on disjoint readings may run side by
    side; returns how many readings have a shadow."""
    height, width = cons.shape
    rows, c0s, c1s = span_buffers(cones, res)
    count = 0
    for i in range(lo, hi):
        ox, oy, r_out = cones[i, 0], cones[i, 1], cones[i, 2]
        stopped[i] = False
        if later:
            stopped2[i] = False
        if attribute and not r_inner[i] < r_out:
            continue
        a, hb = alpha[i], half_fov[i]
        # edge_sector_spans' spans, on the rows that hold a surface that may be silent
        n = listed_row_spans(cones, up_down, i, a, hb, occ_index, gx, gy, res, height, width,
                             rows, c0s, c1s)
        ca, sa = math.cos(a), math.sin(a)
        t_edge = math.tan(hb)
        nb = offsets[i + 1] - offsets[i]
        bin_w = 2.0 * t_edge / nb
        stop = stops[offsets[i]:offsets[i + 1]]
        for k in range(n):
            r = rows[k]
            for j in range(occ_index[r, c0s[k]], occ_index[r, c1s[k] + 1]):
                c = occ_cols[j]
                dx = gx + (c + 0.5) * res - ox
                dy = gy + (r + 0.5) * res - oy
                dist = math.sqrt(dx * dx + dy * dy)
                # Silent with probability q·(1 − visible): a ray stops only at a surface
                # whose orientation is known and that it meets obliquely.
                silent = cons[r, c] * (1.0 - visible(dx, dy, dist, nx[r, c], ny[r, c],
                                                      table)) > 0.5
                silent2 = later and not stopped2[i] and cons2[r, c] * (
                    1.0 - visible(dx, dy, dist, nx2[r, c], ny2[r, c], table)) > 0.5
                if not (silent or silent2):
                    continue
                along = dx * ca + dy * sa
                if along <= 0.0:
                    continue
                if silent2:
                    stopped2[i] = True
                if not silent:
                    continue
                if not stopped[i]:
                    stop[:] = np.inf
                    stopped[i] = True
                    count += 1
                t = (dy * ca - dx * sa) / along
                shade(stop, nb, dist, t, t_edge, res, bin_w)
    return count


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _count_spans(
    rows: I64, c0s: I64, c1s: I64, n: int, row_lo: int, row_hi: int, gx: float, gy: float,
    res: float, ox: float, oy: float, rf: float, ri: float, stopped: bool, ca: float,
    sa: float, t_edge: float, bin_w: float, nb: int, stop: F64, nx: F32, ny: F32, cons: F32,
    table: F64, v_unknown: float, free_out: F32, arcs_out: F32, dbuf: F64, kbuf: I64,
    xbuf: F64,
) -> None:
    """:func:`trace_readings` without ``attribute``: one reading's free and arc counts on
    its spans ``rows, c0s, c1s`` (the rows ``row_lo ≤ r < row_hi``). A span's distances,
    incidences and shadow bins first, in loops without branches (vectorised: the same IEEE
    operations, so the same bits), then its cells: for a reading that no surface stops,
    every cell's visibility, then the adds without branches (vectorised)."""
    tmax = float(table.shape[0] - 1)
    ntab = table.shape[0] - 2
    for k in range(n):
        r = rows[k]
        if r < row_lo or r >= row_hi:
            continue
        c0 = c0s[k]
        w = c1s[k] + 1 - c0
        dy = gy + (r + 0.5) * res - oy
        nxr, nyr = nx[r, c0:c0 + w], ny[r, c0:c0 + w]
        for j in range(w):
            dxv = gx + ((c0 + j) + 0.5) * res - ox
            dv = math.sqrt(dxv * dxv + dy * dy)
            dbuf[j] = dv
            xbuf[j] = abs(dxv * nxr[j] + dy * nyr[j]) / max(dv, 1e-12) * tmax
        if not stopped:
            # Every cell's visibility, then the adds without branches: a cell that gets
            # no evidence adds 0.0, which leaves its float32 value as it was.
            for j in range(w):
                x = xbuf[j]
                kt = min(int(x), ntab)
                f = x - kt
                xbuf[j] = table[kt] * (1.0 - f) + table[kt + 1] * f
            free_r, arcs_r, cons_r = free_out[r, c0:c0 + w], arcs_out[r, c0:c0 + w], cons[r, c0:c0 + w]
            for j in range(w):
                q = cons_r[j]
                free_r[j] += (q * xbuf[j] + (1.0 - q) * v_unknown) if dbuf[j] < rf else 0.0
                arcs_r[j] += 1.0 if dbuf[j] >= ri else 0.0
            continue
        for j in range(w):
            dxv = gx + ((c0 + j) + 0.5) * res - ox
            along = max(dxv * ca + dy * sa, 1e-12)
            kb = math.floor(((dy * ca - dxv * sa) / along + t_edge) / bin_w)
            kbuf[j] = min(max(kb, 0), nb - 1)
        for c in range(c0, c0 + w):
            dist = dbuf[c - c0]
            if dist > stop[kbuf[c - c0]]:
                continue
            if dist < rf:
                q = cons[r, c]
                x = xbuf[c - c0]
                kt = min(int(x), ntab)
                f = x - kt
                free_out[r, c] += (q * (table[kt] * (1.0 - f) + table[kt + 1] * f)
                                   + (1.0 - q) * v_unknown)
            if dist >= ri:
                arcs_out[r, c] += 1.0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _arc_candidates(
    rows: I64, c0s: I64, c1s: I64, n: int, gx: float, gy: float, res: float, ox: float,
    oy: float, ri: float, stopped: bool, ca: float, sa: float, t_edge: float, bin_w: float,
    nb: int, stop: F64, bearings: bool, arc_c: F32, arc_s: F32, free_in: F32,
    arcs_in: F32, ratio: float, cand_r: I64, cand_c: I64,
) -> int:
    """:func:`trace_readings` with ``attribute``: one reading's arc cells on its spans (the
    annulus'), their bearings with ``bearings``, and its candidates (returns how many)."""
    m = 0
    for k in range(n):
        r = rows[k]
        dy = gy + (r + 0.5) * res - oy
        for c in range(c0s[k], c1s[k] + 1):
            dx = gx + (c + 0.5) * res - ox
            d2 = dx * dx + dy * dy
            dist = math.sqrt(d2)
            if stopped:
                along = max(dx * ca + dy * sa, 1e-12)
                kb = math.floor(((dy * ca - dx * sa) / along + t_edge) / bin_w)
                if dist > stop[min(max(kb, 0), nb - 1)]:
                    continue
            if dist >= ri:
                if bearings:
                    inv = 1.0 / max(d2, 1e-24)
                    arc_c[r, c] += (dx * dx - dy * dy) * inv  # cos 2φ
                    arc_s[r, c] += 2.0 * dx * dy * inv  # sin 2φ
                if free_in[r, c] <= ratio * arcs_in[r, c]:
                    cand_r[m] = r
                    cand_c[m] = c
                    m += 1
    return m


@njit(cache=True, inline="always")
def _shadow_frame(alpha: F64, half_fov: F64, offsets: I64,
                  i: int) -> tuple[float, float, float, float, int]:
    """Reading ``i``'s axis ``(cos α, sin α)`` and its shadow profile's bins: the tangent
    of the cone's half width, a bin's width in tangent units and the number of bins."""
    a = alpha[i]
    nb = offsets[i + 1] - offsets[i]
    t_edge = math.tan(half_fov[i])  # bins uniform in tan(bearing − α) across the cone
    return math.cos(a), math.sin(a), t_edge, 2.0 * t_edge / nb, nb


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def echo_candidates(
    cones: F64, up_down: B, r_inner: F64, alpha: F64, half_fov: F64, i: int, gx: float,
    gy: float, res: float, width: int, height: int, offsets: I64, stops: F64, stopped_in: B,
    bearings: bool, arc_c: F32, arc_s: F32, free_in: F32, arcs_in: F32, ratio: float,
    rows: I64, c0s: I64, c1s: I64, cand_r: I64, cand_c: I64,
) -> int:
    """:func:`trace_readings` with ``attribute`` for reading ``i``: its echo's candidate
    cells in ``cand_r, cand_c`` (returns how many; none for a reading with no echo: no arc),
    and with ``bearings`` its arc cells' bearings added to ``arc_c, arc_s``."""
    ox, oy, r_out = cones[i, 0], cones[i, 1], cones[i, 2]
    ri = r_inner[i]
    if not ri < r_out:  # no echo: no arc to attribute
        return 0
    ca, sa, t_edge, bin_w, nb = _shadow_frame(alpha, half_fov, offsets, i)
    # only the arc's cells matter: the annulus' spans
    n = edge_sector_spans(ox, oy, cones[i, 3], cones[i, 4], cones[i, 5], cones[i, 6],
                          up_down[i, 0], up_down[i, 1], ri, r_out, gx, gy, res, width, height,
                          rows, c0s, c1s)
    return _arc_candidates(rows, c0s, c1s, n, gx, gy, res, ox, oy, ri, stopped_in[i], ca, sa,
                           t_edge, bin_w, nb, stops[offsets[i]:offsets[i + 1]], bearings, arc_c,
                           arc_s, free_in, arcs_in, ratio, cand_r, cand_c)


@njit(cache=True, nogil=True, error_model="numpy")
def trace_readings(
    cones: F64, up_down: B, r_inner: F64, r_free: F64, alpha: F64, half_fov: F64,
    gx: float, gy: float, res: float, offsets: I64, stops: F64, stopped_in: B, nx: F32,
    ny: F32, cons: F32, table: F64, v_unknown: float, attribute: bool, bearings: bool,
    free_in: F32, arcs_in: F32, ratio: float, dilution: float, free_out: F32,
    arcs_out: F32, hits: F32, arc_c: F32, arc_s: F32, row_lo: int, row_hi: int,
) -> int:
    """One pass over the readings (module doc), writing only the grid rows
    ``row_lo ≤ r < row_hi`` (without ``attribute``: the rows a thread owns, so two threads
    on two bands add to each cell in reading order, as one would); returns, with
    ``attribute`` (all rows), the echoes with no candidate cell (readings with no echo
    count as such). The readings' shadows are :func:`shadow_profiles`' (``offsets, stops,
    stopped_in``). With ``bearings`` (and ``attribute``) the arc cells add their bearings
    to ``arc_c, arc_s``.

    Speed, not results: the two modes' cell loops are functions of their own
    (:func:`_count_spans`, :func:`_arc_candidates`: the compiler optimises each without the
    other's branches); divisors are never zero, so numpy's error model only drops the
    checks."""
    height, width = free_out.shape
    reach = reach_cells(cones, res)
    rows, c0s, c1s = span_buffers(cones, res)
    cand_r = np.empty(reach * reach, dtype=np.int64)
    cand_c = np.empty(reach * reach, dtype=np.int64)
    dbuf = np.empty(width + 1, dtype=np.float64)
    kbuf = np.empty(width + 1, dtype=np.int64)
    xbuf = np.empty(width + 1, dtype=np.float64)
    lost = 0
    for i in range(cones.shape[0]):
        if attribute:
            m = echo_candidates(cones, up_down, r_inner, alpha, half_fov, i, gx, gy, res,
                                width, height, offsets, stops, stopped_in, bearings, arc_c,
                                arc_s, free_in, arcs_in, ratio, rows, c0s, c1s, cand_r, cand_c)
            if m == 0:  # no echo (no arc to attribute) or no candidate cell
                lost += 1
            else:
                spread_echo(hits, cand_r, cand_c, m, dilution)
            continue
        ox, oy, r_out, s1, s2 = cones[i, 0], cones[i, 1], cones[i, 2], cones[i, 3], cones[i, 5]
        ca, sa, t_edge, bin_w, nb = _shadow_frame(alpha, half_fov, offsets, i)
        # edge_sector_spans' spans, on this call's rows
        r0, r1 = cone_rows(oy, r_out, s1, s2, up_down[i, 0], up_down[i, 1], gy, res, height)
        r0, r1 = max(r0, row_lo), min(r1, row_hi - 1)
        cone_row_spans(ox, oy, r_out, s1, cones[i, 4], s2, cones[i, 6], r0, r1, gx, gy, res,
                       width, c0s, c1s)
        n = 0
        for j in range(r1 - r0 + 1):  # the non-empty ones, in place
            if c0s[j] <= c1s[j]:
                rows[n] = r0 + j
                c0s[n] = c0s[j]
                c1s[n] = c1s[j]
                n += 1
        _count_spans(rows, c0s, c1s, n, row_lo, row_hi, gx, gy, res, ox, oy, r_free[i],
                     r_inner[i], stopped_in[i], ca, sa, t_edge, bin_w, nb,
                     stops[offsets[i]:offsets[i + 1]], nx, ny, cons, table, v_unknown,
                     free_out, arcs_out, dbuf, kbuf, xbuf)
    return lost


class TraceArgs(NamedTuple):
    """:func:`trace_readings`' arguments but the row band, by name (in its order: a call is
    ``trace_readings(*args, row_lo, row_hi)``), so that callers that split a pass (the
    last attribution's lists, :mod:`~pipeline.mapper.kernels.echo_lists`) address them by
    name, not by position."""

    cones: F64
    up_down: B
    r_inner: F64
    r_free: F64
    alpha: F64
    half_fov: F64
    gx: float
    gy: float
    res: float
    offsets: I64
    stops: F64
    stopped_in: B
    nx: F32
    ny: F32
    cons: F32
    table: F64
    v_unknown: float
    attribute: bool
    bearings: bool
    free_in: F32
    arcs_in: F32
    ratio: float
    dilution: float
    free_out: F32
    arcs_out: F32
    hits: F32
    arc_c: F32
    arc_s: F32

    def first(self, cut: int) -> TraceArgs:
        """The arguments for the first ``cut`` readings alone: the per-reading ones cut,
        the offsets one longer (they keep pointing into the same shadow profiles)."""
        return self._replace(
            cones=self.cones[:cut], up_down=self.up_down[:cut], r_inner=self.r_inner[:cut],
            r_free=self.r_free[:cut], alpha=self.alpha[:cut], half_fov=self.half_fov[:cut],
            stopped_in=self.stopped_in[:cut], offsets=self.offsets[:cut + 1])


def cell_lists(cells: B) -> tuple[I32, I32]:
    """The cells of a mask listed row by row (compressed rows): ``(index, cols)``, the
    cells of row ``r`` in columns ``c0 ≤ c ≤ c1`` are ``cols[index[r, c0]:index[r, c1 + 1]]``,
    in column order."""
    index = np.zeros((cells.shape[0], cells.shape[1] + 1), dtype=np.int32)
    np.cumsum(cells, axis=1, out=index[:, 1:])
    index += np.concatenate(([0], np.cumsum(index[:-1, -1]))).astype(np.int32)[:, None]
    cols: I32 = np.nonzero(cells)[1].astype(np.int32)
    return index, cols


def silent_candidates(surfaces: B, consistency: F32) -> tuple[I32, I32]:
    """The surface cells that may be silent to some ray, listed for
    :func:`trace_readings`: ``(occ_index, occ_cols)``. A cell is silent to a ray when
    ``q·(1 − visible) > ½``, which needs ``q > ½``: cells with ``q ≤ ½`` never stop a ray."""
    return cell_lists(surfaces & (consistency > 0.5))

