"""Thrun's forward-model EM iterated to convergence on the default's map (issue 57;
docs/research/forward_walls.md §7). Research only: installed on
:class:`pipeline.mapper.forward.ForwardMapper` by :func:`install` and scored by
:mod:`benchmarks.research.wall_lines_rows` (``--variant em,...``).

After §11's five passes (its map ``M``, its measured detection curve ``p(θ)`` and ``v̄``),
each further pass over the log is one EM iteration (Thrun 2003) on the hypothesis cells
``C`` (§11's final map, with ``cands=both`` also the first map):

* **E-step** (:func:`em_scores`, reading by reading). The reading's cone is traced through
  ``M``: the first cell of ``M`` on each ray stops it (it answers or reflects the pulse
  away), so a cell of ``C`` is *reached* when no cell of ``M`` lies before it on its ray.
  A reached cell met at incidence θ against its normal would answer with ``p = p(θ)``
  (``v̄`` where its orientation is unknown, ``q < ½``). The echo's causes are the reached
  cells of ``M`` on its arc, each with the range likelihood ``L_k = p_k / (2·band)`` (its
  echo anywhere on the arc's band), and a random cause ``L_rand = ρ / r_max`` (anywhere up
  to the sensor's range); responsibility ``e_k = L_k / (L_rand + Σ_{j∈M on the arc} L_j)``
  (a reached cell of ``C`` not in ``M``: as if it were added, its own ``L`` in the sum).
* **M-step** (per cell, the expected log-likelihood ratio occupied / free):
  ``Δ_c = Σ_arc e·ln(L_k / L_rand) + Σ_passed ln(1 − p)``, the second sum over the readings
  that reached ``c`` short of their arc (or with no echo, closer than ``r_max``). ``c`` is
  occupied iff ``Δ_c > 0``; a cell no reading reached keeps its state (``unreached=keep``)
  or is freed (``unreached=free``: Thrun's prior).
* ``ρ``: the first iteration's is the coincidence rate ``f`` of §11's fit (at least
  :data:`RHO_MIN`); then the mean responsibility of the random cause over the echoes
  (``rho=update``, the mixture weight's M-step), or fixed (``rho=<number>``).

Stops when no cell changes (the remaining passes are then skipped: no trace) or after
``iters=N`` iterations. Memory: one float64 score grid and the masks (nothing grows with the
log). Deterministic (readings in log order, one thread).

With ``mstep=linear`` the M-step is §9's linear test instead (``H > w·F + t·scale``): ``H``
the responsibilities (times ``n^(1 − dilution)``, ``n`` the reached cells on the arc), ``F``
the reached passes weighted by §11's ``visible(θ)`` (``v̄`` unknown orientation), ``scale``
the median of §11's attributed weights.

Options (comma separated after ``em``): ``iters=N`` (default 4), ``cands=final|both``,
``mstep=llr|linear``, ``holes=keep|free`` (a freed cell enclosed by the next map's cells
keeps its state: no ray from outside reaches it; the scorer's thinning would turn the hole
into a double wall), ``arcsilent=0|1|near|sigma`` (a reached arc cell that did not cause the echo
also counts ``(1 − e)·ln(1 − p)``; ``near``: only short of the echo's range, the arc's near
half: the first echo masks later ones; ``sigma``: only more than the range noise ``σ_d``
short of the echo's range),
``unreached=keep|free``, ``rho=update|<number>``, ``prior=<log-odds>`` (added to ``Δ``).
:data:`RECORDS` holds, per run, the map after each iteration, the cells changed and the
E-step's CPU seconds (:func:`score_iterations` scores them).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from pipeline.mapper.kernels.attribution import reach_cells, span_buffers
from pipeline.mapper.kernels.forward import incidence_bin
from pipeline.mapper.kernels.specular import (
    MAX_BINS,
    cell_lists,
    listed_row_spans,
    shade,
    shadow_bins,
)
from pipeline.mapper.types import F32, F64, I32, B

RHO_MIN = 0.01  # the random cause's weight at least (a log with no measured coincidences)
P_CLIP = 1e-3  # detection probabilities kept in [P_CLIP, 1 − P_CLIP] (finite logs)
RECORDS: list[dict[str, Any]] = []  # per run: iteration maps, changes, seconds, ρ


@njit(cache=True, nogil=True)
def em_scores(
    cones: F64, up_down: B, r_inner: F64, r_free: F64, r_max: F64, alpha: F64,
    half_fov: F64, gx: float, gy: float, res: float, cand_index: I32, cand_cols: I32, in_map: B, nx: F32,
    ny: F32, cons: F32, p_bin: F64, rho: float, arc_silent: bool, arc_near: bool,
    margin: F64, score: F64, reached: B,
    vis_bin: F64, dilution: float, hits: F64, free: F64,
) -> tuple[float, int]:
    """One E-step over the readings (module doc): adds each reached candidate's expected
    log-likelihood ratio to ``score`` and marks it in ``reached``; returns the sum of the
    random cause's responsibilities over the echoes and how many echoes there were.
    ``p_bin``: ``p(θ)`` per incidence bin and, last, the unknown orientation's. For §9's
    linear test as the M-step (``mstep=linear``) also adds each reached arc cell's
    responsibility times ``n^(1 − dilution)`` (``n`` the reached cells on the arc: §9's
    ``1/n^dilution`` where all are alike) to ``hits`` and each pass's ``vis_bin`` weight
    to ``free``."""
    height, width = cons.shape
    bins = p_bin.shape[0] - 1
    rows, c0s, c1s = span_buffers(cones, res)
    size = reach_cells(cones, res) ** 2
    cell_r = np.empty(size, dtype=np.int64)
    cell_c = np.empty(size, dtype=np.int64)
    cell_d = np.empty(size, dtype=np.float64)
    cell_t = np.empty(size, dtype=np.float64)
    cell_p = np.empty(size, dtype=np.float64)
    cell_b = np.empty(size, dtype=np.int64)
    stop = np.empty(MAX_BINS, dtype=np.float64)
    rand_sum = 0.0
    echoes = 0
    for i in range(cones.shape[0]):
        ox, oy = cones[i, 0], cones[i, 1]
        a, hb = alpha[i], half_fov[i]
        n = listed_row_spans(cones, up_down, i, a, hb, cand_index, gx, gy, res, height, width,
                             rows, c0s, c1s)
        ca, sa = math.cos(a), math.sin(a)
        t_edge = math.tan(hb)
        nb = shadow_bins(hb, cones[i, 2], res)
        bin_w = 2.0 * t_edge / nb
        stop[:nb] = np.inf
        m = 0
        for k in range(n):
            r = rows[k]
            dy = gy + (r + 0.5) * res - oy
            for j in range(cand_index[r, c0s[k]], cand_index[r, c1s[k] + 1]):
                c = cand_cols[j]
                dx = gx + (c + 0.5) * res - ox
                along = dx * ca + dy * sa
                if along <= 0.0:
                    continue
                dist = math.sqrt(dx * dx + dy * dy)
                t = (dy * ca - dx * sa) / along
                if in_map[r, c]:  # only the map's cells stop rays
                    shade(stop, nb, dist, t, t_edge, res, bin_w)
                cell_r[m] = r
                cell_c[m] = c
                cell_d[m] = dist
                cell_t[m] = t
                m += 1
        # reached candidates, their detection probability; the echo's mixture (densities
        # over the range: a cause's echo lies on its arc's band, a random one anywhere)
        has_echo = r_inner[i] < cones[i, 2]
        width_inv = 1.0 / (cones[i, 2] - r_inner[i]) if has_echo else 0.0
        l_rand = rho / r_max[i]
        # with ``arc_silent``: the arc cells that did not answer count as silent up to the
        # echo's range (near only: the arc's near half; a later answer is masked)
        near_end = math.inf if not arc_near else 0.5 * (r_inner[i] + cones[i, 2]) - margin[i]
        total = l_rand
        n_arc = 0
        for j in range(m):
            kb = math.floor((cell_t[j] + t_edge) / bin_w)
            if cell_d[j] > stop[min(max(kb, 0), nb - 1)]:
                cell_p[j] = -1.0  # not reached
                continue
            r, c = cell_r[j], cell_c[j]
            b = bins
            if cons[r, c] >= 0.5:
                dx = gx + (c + 0.5) * res - ox
                dy = gy + (r + 0.5) * res - oy
                b = incidence_bin(dx, dy, cell_d[j], nx[r, c], ny[r, c], bins)
            cell_p[j] = p_bin[b]
            cell_b[j] = b
            if has_echo and cell_d[j] >= r_inner[i]:
                n_arc += 1
                if in_map[r, c]:
                    total += p_bin[b] * width_inv
        if has_echo:
            echoes += 1
            rand_sum += l_rand / total
        for j in range(m):
            p = cell_p[j]
            if p < 0.0:
                continue
            r, c = cell_r[j], cell_c[j]
            if has_echo and cell_d[j] >= r_inner[i]:
                lk = p * width_inv
                e = lk / total if in_map[r, c] else lk / (total + lk)
                score[r, c] += e * math.log(lk / l_rand)
                hits[r, c] += e * n_arc ** (1.0 - dilution)
                if arc_silent and cell_d[j] < near_end:
                    score[r, c] += (1.0 - e) * math.log1p(-p)
                reached[r, c] = True
            elif cell_d[j] < r_free[i]:
                score[r, c] += math.log1p(-p)
                free[r, c] += vis_bin[cell_b[j]]
                reached[r, c] = True
    return rand_sum, echoes


def detection_bins(p_reach: F64, v_unknown: float) -> F64:
    """``p(θ)`` per bin and ``v̄`` last, clipped to [P_CLIP, 1 − P_CLIP]."""
    out: F64 = np.clip(np.append(p_reach, v_unknown), P_CLIP, 1.0 - P_CLIP)
    return out


def m_step(current: B, score: F64, reached: B, prior: float, free_unreached: bool,
           keep_holes: bool = False) -> B:
    """The next map over the candidates: occupied iff ``Δ + prior > 0`` where reached;
    elsewhere kept (or freed with ``free_unreached``). With ``keep_holes`` a freed cell
    enclosed by the next map's cells (a hole: no ray from outside reaches it) keeps its
    state."""
    from scipy.ndimage import binary_fill_holes

    keep = np.zeros_like(current) if free_unreached else current
    out: B = np.where(reached, score + prior > 0.0, keep)
    if keep_holes:
        out |= current & binary_fill_holes(out)
    return out


def install(variant: str) -> None:
    """Patch ForwardMapper with the EM iterations (``variant`` as the module doc)."""
    import pipeline.mapper.forward as fwd
    from pipeline.mapper.free_space import cone_table
    from pipeline.mapper.reading_features import distance_sigma
    from pipeline.stages import reading_quality as rq

    opts = dict(v.split("=", 1) for v in variant.split(",") if v and v != "em")
    iters = int(opts.get("iters", 4))
    both = opts.get("cands", "final") == "both"
    free_unreached = opts.get("unreached", "keep") == "free"
    rho_opt = opts.get("rho", "update")
    prior = float(opts.get("prior", 0.0))
    arc_silent = opts.get("arcsilent", "0") in ("1", "near", "sigma")
    arc_near = opts.get("arcsilent", "0") in ("near", "sigma")
    arc_sigma = opts.get("arcsilent", "0") == "sigma"
    linear = opts.get("mstep", "llr") == "linear"
    keep_holes = opts.get("holes", "keep") == "keep"
    base = fwd.ForwardMapper
    begin, integrate, occupied = base.begin_pass, base._integrate_group, base.occupied

    def em_begin(self: Any, index: int) -> None:
        if index < 5:
            begin(self, index)
            return
        st = self.__dict__.setdefault("_em", None)
        if st is None:  # after pass 4: §11's map and curve
            final = occupied(self)
            cands = final | self.surfaces if both else final
            floor = fwd.fit_detection(self.stats)[3]
            st = self._em = {
                "map": final, "cands": cands, "lists": cell_lists(cands),
                "p": detection_bins(self.p_reach, self.v_unknown),
                "rho": max(RHO_MIN, floor) if rho_opt == "update" else float(rho_opt),
                "vis": np.append(fwd.pass_evidence(self.p_reach), self.v_unknown),
                "scale": float(np.median(self.hits2[self.hits2 > 0])),
                "record": {"maps": [final], "changed": [], "cpu": [], "rho": [],
                           "converged": None},
                "active": True,
            }
            RECORDS.append(st["record"])
        else:
            self._em_finish()
        self.pass_index = index
        self._group_index = 0
        st["score"] = np.zeros(self.grid.shape)
        st["hits"] = np.zeros(self.grid.shape)
        st["free"] = np.zeros(self.grid.shape)
        st["reached"] = np.zeros(self.grid.shape, dtype=bool)
        st["rand"], st["echoes"], st["cpu"] = 0.0, 0, 0.0

    def em_finish(self: Any) -> None:
        """The M-step of the pass just streamed (once)."""
        st = self._em
        if st is None or not st["active"] or "score" not in st:
            return
        score = st["score"]
        if linear:  # §9's linear test on the responsibilities and the reached passes
            cfg = self.config
            score = st["hits"] - cfg.attr_free_weight * st["free"] - cfg.attr_threshold * st[
                "scale"]
        new = m_step(st["map"], score, st["reached"], prior, free_unreached,
                     keep_holes) & st["cands"]
        changed = int((new != st["map"]).sum())
        rec = st["record"]
        rec["changed"].append(changed)
        rec["cpu"].append(st["cpu"])
        rec["rho"].append(st["rho"])
        rec["maps"].append(new)
        st["map"] = new
        del st["score"]
        if rho_opt == "update" and st["echoes"]:
            st["rho"] = max(RHO_MIN, st["rand"] / st["echoes"])
        if changed == 0:
            st["active"] = False  # converged: the remaining passes do nothing
            rec["converged"] = len(rec["changed"])

    def em_integrate(self: Any, group: Any) -> None:
        if self.pass_index < 5:
            integrate(self, group)
            return
        st = self._em
        if not st["active"]:
            return
        started = time.thread_time()
        g, cfg = self.grid, self.config
        cat = group.cat
        d = np.where(group.codes == rq.OK, cat.range_m, 0.0)
        band = np.maximum(cfg.attr_band_sigmas * distance_sigma(d, cfg), 0.5 * g.resolution)
        silent = (group.codes == rq.MAX_RANGE) & np.isfinite(cat.max_range)
        free_r = np.where(silent, cat.max_range - cfg.eps_max, group.free_radius)
        outer = np.where(silent, free_r, np.where(d > 0.0, d + band, 0.0))
        rows, cones, up_down = cone_table(cat, outer)
        r_inner = np.where(d > 0.0, np.maximum(d - band, 0.0), np.inf)[rows]
        half = np.minimum(0.5 * cat.fov[rows], 0.5 * math.pi - 1e-9)
        margin = distance_sigma(d, cfg) if arc_sigma else np.zeros(len(d))
        # the random cause's range density: uniform up to the sensor's range
        r_max = np.where(np.isfinite(cat.max_range), cat.max_range, np.maximum(outer, 1.0))
        idx, cols = st["lists"]
        rand, echoes = em_scores(
            cones, up_down, r_inner, free_r[rows], r_max[rows], cat.alpha[rows], half, g.origin_x,
            g.origin_y, g.resolution, idx, cols, st["map"], self.nx, self.ny,
            self.consistency, st["p"], st["rho"], arc_silent, arc_near, margin[rows], st["score"], st["reached"],
            st["vis"], cfg.attr_dilution, st["hits"], st["free"])
        st["rand"] += rand
        st["echoes"] += echoes
        st["cpu"] += time.thread_time() - started

    def em_occupied(self: Any) -> B:
        st = self.__dict__.get("_em")
        if st is None:
            return occupied(self)
        self._em_finish()
        out: B = st["map"]
        return out

    base.passes = 5 + iters
    base.begin_pass = em_begin  # type: ignore[method-assign]
    base._integrate_group = em_integrate  # type: ignore[method-assign]
    base.occupied = em_occupied  # type: ignore[method-assign]
    base._em_finish = em_finish  # type: ignore[attr-defined]


def _occupied_pixels(run_dir: Path) -> tuple[bytes, int, np.ndarray]:
    """The run's map.pgm: header bytes, offset of the pixels, pixels (rows as stored)."""
    data = (run_dir / "map.pgm").read_bytes()
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:  # P5, width, height, maxval (no comments in our writer)
        while data[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while not data[pos:pos + 1].isspace():
            pos += 1
        fields.append(data[start:pos])
    pos += 1
    w, h = int(fields[1]), int(fields[2])
    pix = np.frombuffer(data, dtype=np.uint8, count=w * h, offset=pos).reshape(h, w)
    return data[:pos], pos, pix


def score_iterations(run_dir: Path, truth: Path, traj: Path | None, reach: float | None,
                     octo: float) -> list[tuple[float, float, float, float]]:
    """F1 (P, R) and lead of every iteration's map of the last run (:data:`RECORDS`): the
    run's map.pgm with the occupied cells replaced (freed cells as free), scored by
    ``evaluate_run`` in a copy of the run directory."""
    import shutil

    from pipeline.tools.evaluate import evaluate_run

    rec = RECORDS[-1]
    final = rec["maps"][-1]
    head, _, pix = _occupied_pixels(run_dir)
    flip = not np.array_equal(pix == 0, final)
    if flip and not np.array_equal(np.flipud(pix == 0), final):
        raise RuntimeError("map.pgm's occupied cells are not the EM's final map")
    out = []
    tmp = run_dir.with_name(run_dir.name + "-iter")
    for mask in rec["maps"]:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(run_dir, tmp)
        m = np.flipud(mask) if flip else mask
        new = pix.copy()
        new[(pix == 0) & ~m] = 254
        new[m] = 0
        (tmp / "map.pgm").write_bytes(head + new.tobytes())
        ev = evaluate_run(tmp, truth, trajectory=traj, tolerance_m=0.10, sensor_reach_m=reach)
        out.append((ev.f1, ev.precision, ev.recall, ev.f1 - octo))
    shutil.rmtree(tmp, ignore_errors=True)
    return out


def iteration_table(rows_json: Path) -> str:
    """Per group, the mean lead over OctoMap (worst row) of every iteration's map, and the
    cells changed and E-step CPU seconds summed over the rows, from ``wall_lines_rows``'s
    ``rows.json`` (iteration 0 = §11's map)."""
    import json

    from benchmarks.research.wall_lines_rows import GROUPS

    it = json.loads(rows_json.read_text())["iterations"]
    n = max(len(v["rows"]) for v in it.values())
    lines = ["| group | " + " | ".join(f"it {k}" for k in range(n)) + " |",
             "|---|" + "---:|" * n]
    for group, names in GROUPS.items():
        cells = []
        for k in range(n):
            # a converged row keeps its last map
            leads = [it[m]["rows"][min(k, len(it[m]["rows"]) - 1)][3] for m in names if m in it]
            cells.append(f"{sum(leads) / len(leads):+.3f} ({min(leads):+.3f})" if leads else "")
        lines.append(f"| {group} | " + " | ".join(cells) + " |")
    changed = [sum(v["changed"][k] for v in it.values() if k < len(v["changed"]))
               for k in range(n - 1)]
    cpu = [sum(v["cpu"][k] for v in it.values() if k < len(v["cpu"])) for k in range(n - 1)]
    lines.append("| cells changed (all rows) | – | " + " | ".join(map(str, changed)) + " |")
    lines.append("| E-step CPU s (all rows) | – | " + " | ".join(f"{c:.2f}" for c in cpu)
                 + " |")
    return "\n".join(lines)


def row_table(rows_json: Path) -> str:
    """Per row, F1 of every iteration's map (iteration 0 = §11's) and the cells changed."""
    import json

    it = json.loads(rows_json.read_text())["iterations"]
    return "\n".join(
        f"| {name} | " + " | ".join(f"{r[0]:.3f}" for r in v["rows"])
        + f" | {v['changed']} |" for name, v in it.items())


DISTANCE_BINS = (0, 1, 2, 3, 5, 10)  # cells from the nearest true wall cell


def freed_by_distance(variant: str, names: list[str]) -> None:
    """Run the rows ``names`` with ``variant`` and print, per iteration, the cells freed and
    added by their distance to the nearest true wall cell (the truth resampled to the run's
    grid, :data:`DISTANCE_BINS`), beside the map's cells before the first."""
    import dataclasses
    from itertools import pairwise

    from scipy.ndimage import distance_transform_edt

    from benchmarks.compare_methods import load_config_for
    from benchmarks.research.wall_lines_rows import ROWS
    from formats.writers.nav2_map import load_nav2_map
    from pipeline.methods import Method
    from pipeline.run import run
    from pipeline.tools.evaluate import resample_classes

    install(variant)
    edges = [*DISTANCE_BINS, math.inf]
    for name, log, truth, _ in ROWS:
        if name not in names:
            continue
        cfg = load_config_for(log, None)
        cfg = cfg.replace(mapper=dataclasses.replace(cfg.mapper, method=Method.FORWARD))
        out = Path("build/em_flips") / name
        run(log, out, cfg, force=True)
        maps = RECORDS[-1]["maps"]
        t_map, r_map = load_nav2_map(truth), load_nav2_map(out / "map.yaml")
        t, _ = resample_classes(t_map.classes, t_map.grid, r_map.grid)
        dist = distance_transform_edt(t != 1)

        def hist(mask: B, dist: F64 = dist) -> list[int]:
            d = dist[mask]
            return [int(((d >= lo) & (d < hi)).sum()) for lo, hi in pairwise(edges)]

        print(f"{name}: cells at {list(DISTANCE_BINS)}+ cells from a true wall: {hist(maps[0])}")
        for k in range(1, len(maps)):
            print(f"  iteration {k}: freed {hist(maps[k - 1] & ~maps[k])}, "
                  f"added {hist(maps[k] & ~maps[k - 1])}")


if __name__ == "__main__":
    import sys

    if sys.argv[1] == "--flips":  # --flips VARIANT ROW ...
        freed_by_distance(sys.argv[2], sys.argv[3:])
    else:
        print(iteration_table(Path(sys.argv[1])))
        if "--rows" in sys.argv:
            print(row_table(Path(sys.argv[1])))
