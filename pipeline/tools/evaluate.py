"""Evaluate a run directory against a ground-truth map: how well the map matches the world.

``evaluate_run`` reads a run's ``map.yaml``/``map.pgm`` (nav2), ``features.parquet``,
``metrics.json`` and ``config.toml`` and a ground-truth nav2 map (the simulator writes one
beside every simulated log), and scores the run's map on the truth grid:

* **Resampling.** The run map is resampled onto the truth grid by world coordinates: each
  truth cell takes the class of the run cell that contains its centre (for aligned grids of
  equal resolution that is the nearest cell centre); truth cells outside the run map are
  unknown. When the run grid is *finer* than the truth grid, a truth cell is also occupied
  when any occupied run cell's centre lies inside it, so a one-cell-thick wall is not lost
  by decimation. Where the run map reaches beyond the truth map, the truth grid is extended
  (same alignment and resolution, truth unknown there), so phantom walls outside the truth
  map still count against precision (``run_occupied_outside`` counts them). All cell
  counts are in truth-grid cells.
* **Walls, matched one to one** (:mod:`pipeline.tools.wall_matching`, the Berkeley
  boundary benchmark's rule). Both maps' occupied cells, less those inside true solids
  (unobservable), are thinned to one-cell lines: the walls. A run wall cell and a
  true wall cell correspond when their centres are within ``tolerance_m``; a maximum
  one-to-one matching pairs them. Precision: of the run's wall cells, the fraction
  matched. Recall: of the true wall cells *in scope*, the fraction matched. In scope means
  within ``reach`` of a trajectory pose (``reach`` = the run's largest sensor range, or
  ``sensor_reach_m``); with no trajectory or no known reach every true wall cell is in
  scope and a note says so. F1 is their harmonic mean (an undefined precision or recall
  counts as 0, with a note). A wall's drawn thickness does not change its score; a second
  line along a matched wall finds no partner and costs precision.
* **Free space.** Free accuracy: of the run's free cells on known truth cells, the fraction
  free in the truth. Unknown fraction: of the truth's known cells in scope, the fraction
  the run left unknown.
* **Aligned scores** (with a true trajectory). A run on drifting odometry builds its map
  in its own frame, anchored where the odometry started; a small heading error early on
  turns the whole map. ``aligned`` scores the map again after moving it by the rigid
  motion that best lays the run's trajectory onto the true one (the SE(2) alignment of
  the ATE, :func:`pipeline.tools.trajectory_error.align_se2`), so it measures the map's shape,
  not where its frame was anchored (:func:`move_classes`).
* **Features.** Mean (and median) distance, m, from each feature mean to the nearest true
  occupied cell centre, and the paper's mean feature variance (m²) from ``metrics.json``.

Values that cannot be computed are ``None``, never NaN; everything is deterministic.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from formats.arrays import F64, I8, B
from formats.errors import ConfigError, FormatError, InputError
from formats.map_types import DEFAULT_MAX_CELLS, GridSpec
from formats.tables import text_table
from formats.writers.trajectory_csv import read_trajectory
from pipeline.se2 import inverse, transform_points
from pipeline.stages.metrics_schema import Metrics, finite, read_metrics
from pipeline.tools.wall_matching import interior, match, thin

__all__ = [
    "RUN_FILES",
    "Evaluation",
    "evaluate_maps",
    "evaluate_run",
    "resample_classes",
    "run_sensor_reach",
]


#: Files evaluate needs in a run directory (config.toml is optional: only the reach).
RUN_FILES = ("map.yaml", "metrics.json", "features.parquet")

OCCUPIED, FREE, UNKNOWN = 1, 0, -1
#: The rule that pairs run and true wall cells (``Evaluation.matching``).
MATCHING = "one-to-one, thinned walls"
#: What an evaluation written before the rule was scored with.
MATCHING_BEFORE = "distance to the nearest cell"


def _within(dist: F64, tolerance_m: float) -> B:
    # Distances are sqrt of sums of squared multiples of the resolution: allow for rounding,
    # so "two cells away" at 0.05 m still counts within a 0.10 m tolerance.
    return dist <= tolerance_m * (1.0 + 1e-9) + 1e-12


def _ratio(num: int, den: int) -> float | None:
    return None if den == 0 else num / den


@dataclass(frozen=True)
class Evaluation:
    """The scores of one run against one ground truth; see the module docstring.

    Fractions are in [0, 1]; distances in m; ``None`` = not computable (see ``notes``).
    """

    run_dir: str
    truth: str
    trajectory: str | None
    tolerance_m: float
    reach_m: float | None
    reach_source: str  # "argument", "metrics.json", "config.toml" or "unknown"
    recall_scope: str  # "within_reach" or "all"
    precision: float
    recall: float
    f1: float
    free_accuracy: float | None
    unknown_fraction: float | None
    run_occupied: int  # run wall cells (thinned, truth-grid cells, incl. the outside ones)
    run_occupied_matched: int
    run_occupied_outside: int  # of run_occupied, those outside the truth map
    truth_occupied_in_scope: int  # true wall cells (surfaces, thinned) in scope
    truth_occupied_matched: int
    run_free: int  # run free cells on known truth cells
    run_free_correct: int
    truth_known_in_scope: int
    run_unknown_in_scope: int
    features: int
    feature_distance_mean_m: float | None
    feature_distance_median_m: float | None
    mean_feature_variance_m2: float | None  # the paper's metric, from metrics.json
    notes: tuple[str, ...] = ()
    # Why the map is wrong (cell counts; see :func:`error_breakdown`).
    false_occupied: dict[str, int] = field(default_factory=dict)
    missed: dict[str, int] = field(default_factory=dict)
    # True walls the path mostly saw beyond ``incidence_deg`` off their normal, and how
    # many of them the map missed (cell counts; :mod:`pipeline.tools.oblique_walls`).
    oblique: dict[str, float] = field(default_factory=dict)
    # ATE/RPE of the run's trajectory.csv against --truth-trajectory (pipeline.tools.trajectory_error)
    trajectory_error: dict[str, Any] | None = None
    # The map scored again after the trajectory's SE(2) alignment (module docstring):
    # precision, recall, f1 and the alignment [tx, ty, θ] (m, m, rad).
    aligned: dict[str, Any] | None = None
    # How run and true wall cells were paired (MATCHING; MATCHING_BEFORE for older files).
    matching: str = MATCHING

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: floats rounded to 12 significant digits, notes as a list."""
        out: dict[str, Any] = {}
        for k, v in asdict(self).items():
            if isinstance(v, float):
                v = float(f"{v:.12g}")
            elif isinstance(v, tuple):
                v = list(v)
            out[k] = v
        return out

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str | Path | None = None) -> Evaluation:
        """Rebuild from :meth:`to_dict` output; FormatError (naming ``source``) if malformed."""
        if not isinstance(data, dict):
            raise FormatError("evaluation is not a JSON object", source)
        names = [f.name for f in fields(cls)]
        optional = ("notes", "false_occupied", "missed", "oblique", "trajectory_error",
                    "aligned", "matching")
        missing = [n for n in names if n not in data and n not in optional]
        if missing:
            raise FormatError(f"evaluation has no {', '.join(missing)}", source)
        kwargs = {n: data[n] for n in names if n in data}
        kwargs["notes"] = tuple(str(n) for n in data.get("notes", ()))
        kwargs["matching"] = str(data.get("matching", MATCHING_BEFORE))
        for n in ("false_occupied", "missed"):
            part = data.get(n, {})
            if not isinstance(part, dict) or not all(isinstance(v, int) for v in part.values()):
                raise FormatError(f"evaluation '{n}' is not a table of cell counts", source)
            kwargs[n] = {str(k): int(v) for k, v in part.items()}
        part = data.get("oblique", {})
        if not isinstance(part, dict) or not all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in part.values()):
            raise FormatError("evaluation 'oblique' is not a table of numbers", source)
        kwargs["oblique"] = {str(k): float(v) for k, v in part.items()}
        for n in ("precision", "recall", "f1", "tolerance_m"):
            v = kwargs[n]
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise FormatError(f"evaluation '{n}' is not a number: {v!r}", source)
            kwargs[n] = float(v)
        return cls(**kwargs)

    def format_table(self) -> str:
        """A human-readable two-column table."""

        def pct(v: float | None) -> str:
            return "n/a" if v is None else f"{100.0 * v:.1f} %"

        def num(v: float | None, unit: str) -> str:
            return "n/a" if v is None else f"{v:.4g} {unit}"

        scope = (
            f"within {self.reach_m:.3g} m of the trajectory"
            if self.recall_scope == "within_reach" and self.reach_m is not None
            else "all true occupied cells"
        )
        rows = [
            ("run", self.run_dir),
            ("truth", self.truth),
            ("trajectory", self.trajectory or "-"),
            ("tolerance", f"{self.tolerance_m:.3g} m"),
            ("matching", self.matching),
            ("recall scope", scope),
            ("precision", f"{pct(self.precision)}  ({self.run_occupied_matched}"
                          f"/{self.run_occupied} run wall cells)"),
            ("recall", f"{pct(self.recall)}  ({self.truth_occupied_matched}"
                       f"/{self.truth_occupied_in_scope} true wall cells)"),
            ("F1", f"{self.f1:.4f}"),
            ("free accuracy", f"{pct(self.free_accuracy)}  ({self.run_free_correct}"
                              f"/{self.run_free} run free cells)"),
            ("unknown fraction", f"{pct(self.unknown_fraction)}  ({self.run_unknown_in_scope}"
                                 f"/{self.truth_known_in_scope} known truth cells)"),
            ("features", str(self.features)),
            ("feature distance", f"mean {num(self.feature_distance_mean_m, 'm')}, "
                                 f"median {num(self.feature_distance_median_m, 'm')}"),
            ("mean feature variance", num(self.mean_feature_variance_m2, "m²")),
        ]
        for title, part in (("false occupied", self.false_occupied), ("missed walls", self.missed)):
            if part:
                total = sum(part.values())
                rows.append((title, ", ".join(
                    f"{k.replace('_', ' ')} {v} ({pct(v / total) if total else 'n/a'})"
                    for k, v in part.items())))
        if self.oblique:
            o = self.oblique
            rows.append((f"seen obliquely (> {o['incidence_deg']:g}°)",
                         f"{o['walls']:.0f} of {self.truth_occupied_in_scope} true wall cells "
                         f"in scope; {o['missed']:.0f} of them missed, "
                         f"{o['missed_seen_free']:.0f} seen free"))
        if self.trajectory_error is not None:
            from pipeline.tools.trajectory_error import TrajectoryError

            te = dict(self.trajectory_error)
            te["alignment"] = tuple(te["alignment"])
            rows += TrajectoryError(**te).table_rows()
        if self.aligned is not None:
            tx, ty, th = self.aligned["alignment"]
            rows.append(("F1 aligned", f"{self.aligned['f1']:.4f}  (precision "
                         f"{pct(self.aligned['precision'])}, recall {pct(self.aligned['recall'])}; "
                         f"the map moved by its trajectory's alignment: {math.degrees(th):.2f}°, "
                         f"({tx:.3f}, {ty:.3f}) m)"))
        lines = text_table(None, rows)
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


# --------------------------------------------------------------------------- inputs


def run_max_cells(run_dir: Path) -> int:
    """The run's own ``[grid] max_cells`` (its config.toml), else the default: the bound of
    every grid evaluate builds."""
    cfg_path = run_dir / "config.toml"
    if not cfg_path.is_file():
        return DEFAULT_MAX_CELLS
    from pipeline.config import load_config

    try:
        return load_config(cfg_path).grid.max_cells
    except ConfigError as err:
        raise FormatError(f"run configuration is unreadable: {err.reason}", cfg_path) from err


def run_sensor_reach(run_dir: Path, metrics: Metrics) -> tuple[float | None, str]:
    """The run's largest sensor range, m, and where it came from.

    Looked up in metrics.json (``input.max_range_m``, when the run recorded one), then in
    config.toml (``[sensors] max_range``, the mounts'
    ``max_range`` and the preset's). Returns ``(None, "unknown")`` when neither has one:
    a range that came from the log itself is not recorded in config.toml.
    """
    logged = finite(metrics.get("input", {}).get("max_range_m"))
    if logged is not None and logged > 0:
        return logged, "metrics.json"
    cfg_path = run_dir / "config.toml"
    if not cfg_path.is_file():
        return None, "unknown"
    from formats.presets import PRESETS
    from pipeline.config import load_config

    try:
        cfg = load_config(cfg_path)
    except ConfigError as err:
        raise FormatError(f"run configuration is unreadable: {err.reason}", cfg_path) from err
    sc = cfg.sensors
    mounts = list(sc.mounts) + list(PRESETS.get(sc.preset, ()))
    found = [v for v in [sc.max_range, *(m.max_range for m in mounts)] if v > 0]
    if found:
        return max(found), "config.toml"
    return None, "unknown"


# --------------------------------------------------------------------------- resampling


def _centres(origin: float, resolution: float, n: int) -> F64:
    return origin + (np.arange(n, dtype=np.float64) + 0.5) * resolution


def _index(
    coord: npt.NDArray[np.floating[Any]], origin: float, resolution: float, n: int
) -> tuple[npt.NDArray[np.int64], B]:
    """Index of the cell containing each coordinate, and whether it lies on the grid."""
    idx = np.floor((coord - origin) / resolution).astype(np.int64)
    return idx, (idx >= 0) & (idx < n)


def resample_classes(
    classes: I8, src: GridSpec, dst: GridSpec
) -> tuple[I8, int]:
    """``classes`` (1/0/−1 on ``src``) on the ``dst`` grid, and the count of occupied source
    cells whose centre lies outside ``dst``. See the module docstring for the rules."""
    out = np.full(dst.shape, UNKNOWN, dtype=np.int8)
    cols, cok = _index(_centres(dst.origin_x, dst.resolution, dst.width), src.origin_x,
                       src.resolution, src.width)
    rows, rok = _index(_centres(dst.origin_y, dst.resolution, dst.height), src.origin_y,
                       src.resolution, src.height)
    out[np.ix_(rok, cok)] = classes[np.ix_(rows[rok], cols[cok])]
    occ_r, occ_c = np.nonzero(classes == OCCUPIED)
    dr, rin = _index(src.origin_y + (occ_r + 0.5) * src.resolution, dst.origin_y,
                     dst.resolution, dst.height)
    dc, cin = _index(src.origin_x + (occ_c + 0.5) * src.resolution, dst.origin_x,
                     dst.resolution, dst.width)
    inside = rin & cin
    if src.resolution < dst.resolution * (1.0 - 1e-9):
        out[dr[inside], dc[inside]] = OCCUPIED  # pooling: a finer run keeps thin walls
    return out, int((~inside).sum())


def move_classes(
    classes: I8, grid: GridSpec, motion: tuple[float, float, float],
    max_cells: int = DEFAULT_MAX_CELLS,
) -> tuple[I8, GridSpec]:
    """``classes`` moved rigidly by ``motion`` = ``(tx, ty, θ)`` (a point p goes to
    R(θ)·p + t), on an axis-aligned grid of the same resolution that covers the moved map:
    each cell takes the class of the source cell under its centre, and each occupied source
    cell also marks the cell its centre moves into, so a turned wall stays unbroken."""
    res = grid.resolution
    xs = np.array([0.0, grid.width, 0.0, grid.width]) * res + grid.origin_x
    ys = np.array([0.0, 0.0, grid.height, grid.height]) * res + grid.origin_y
    mx, my = transform_points(motion, xs, ys)
    # 1e-9 of a cell: an edge that lands on a cell boundary (a quarter turn) adds no cell.
    ox = math.floor(mx.min() / res + 1e-9) * res
    oy = math.floor(my.min() / res + 1e-9) * res
    dst = GridSpec(ox, oy, res, math.ceil((mx.max() - ox) / res - 1e-9),
                   math.ceil((my.max() - oy) / res - 1e-9))
    check_cells(dst, max_cells, "the aligned run map")
    # Each cell centre moved back into the source map.
    sx, sy = transform_points(inverse(motion), _centres(ox, res, dst.width)[None, :],
                              _centres(oy, res, dst.height)[:, None])
    cols, cok = _index(sx, grid.origin_x, res, grid.width)
    rows, rok = _index(sy, grid.origin_y, res, grid.height)
    out = np.full(dst.shape, UNKNOWN, dtype=np.int8)
    ok = cok & rok
    out[ok] = classes[rows[ok], cols[ok]]
    occ_r, occ_c = np.nonzero(classes == OCCUPIED)
    qx, qy = transform_points(motion, _centres(grid.origin_x, res, grid.width)[occ_c],
                              _centres(grid.origin_y, res, grid.height)[occ_r])
    dc, cin = _index(qx, ox, res, dst.width)
    dr, rin = _index(qy, oy, res, dst.height)
    out[dr[cin & rin], dc[cin & rin]] = OCCUPIED
    return out, dst


def check_cells(grid: GridSpec, max_cells: int, what: str) -> None:
    """ConfigError (before anything is allocated) when ``grid`` exceeds ``max_cells``."""
    if grid.width * grid.height > max_cells:
        raise ConfigError(
            f"{what} would have {grid.width}x{grid.height} cells at {grid.resolution:g} m, "
            f"more than grid.max_cells = {max_cells}: are the two maps in the same frame?"
        )


def _extended(truth: GridSpec, run: GridSpec) -> tuple[GridSpec, tuple[slice, slice]]:
    """The truth grid grown (same alignment and resolution) to cover the run grid too, and
    the truth map's window (rows, cols) inside it."""
    res = truth.resolution

    def pad(lo: float) -> int:
        # Snap to whole cells; 1e-9 keeps an exactly aligned edge from adding a cell.
        return max(0, math.ceil(lo / res - 1e-9))

    left = pad(truth.origin_x - run.origin_x)
    bottom = pad(truth.origin_y - run.origin_y)
    right = pad(run.origin_x + run.width * run.resolution - (truth.origin_x + truth.width * res))
    top = pad(run.origin_y + run.height * run.resolution - (truth.origin_y + truth.height * res))
    grid = GridSpec(truth.origin_x - left * res, truth.origin_y - bottom * res, res,
                    truth.width + left + right, truth.height + bottom + top)
    return grid, (slice(bottom, bottom + truth.height), slice(left, left + truth.width))


def _distance_to(mask: B, resolution: float) -> F64:
    """Distance, m, from every cell centre to the nearest True cell centre (inf if none)."""
    from scipy.ndimage import distance_transform_edt

    if not mask.any():
        return np.full(mask.shape, np.inf)
    return np.asarray(distance_transform_edt(~mask, sampling=resolution), dtype=np.float64)


def _in_reach(grid: GridSpec, poses_xy: F64, reach_m: float) -> B:
    """Cells whose centre is within ``reach_m`` of any pose (exact, k-d tree)."""
    from scipy.spatial import cKDTree

    xs = _centres(grid.origin_x, grid.resolution, grid.width)
    ys = _centres(grid.origin_y, grid.resolution, grid.height)
    # Poses farther than the reach from the grid's box cannot reach any cell.
    near = (
        (poses_xy[:, 0] >= xs[0] - reach_m) & (poses_xy[:, 0] <= xs[-1] + reach_m)
        & (poses_xy[:, 1] >= ys[0] - reach_m) & (poses_xy[:, 1] <= ys[-1] + reach_m)
    )
    pts = np.unique(poses_xy[near], axis=0)
    if pts.shape[0] == 0:
        return np.zeros(grid.shape, dtype=bool)
    gx, gy = np.meshgrid(xs, ys)
    dist, _ = cKDTree(pts).query(
        np.column_stack([gx.ravel(), gy.ravel()]), k=1,
        distance_upper_bound=reach_m * (1.0 + 1e-9) + 1e-12,
    )
    return np.asarray(np.isfinite(dist), dtype=bool).reshape(grid.shape)


# --------------------------------------------------------------------------- scoring


def evaluate_maps(
    run_classes: I8,
    run_grid: GridSpec,
    truth_classes: I8,
    truth_grid: GridSpec,
    *,
    tolerance_m: float,
    poses_xy: F64 | None,
    reach_m: float | None,
    feature_xy: F64,
    max_cells: int = DEFAULT_MAX_CELLS,
    oblique_deg: float | None = None,
) -> tuple[dict[str, Any], tuple[str, ...]]:
    """The map and feature scores (the numeric fields of :class:`Evaluation`) and notes;
    with ``oblique_deg`` and a trajectory also the obliquely seen walls (``oblique``).
    ConfigError when the grid covering both maps (at the truth's resolution) would have
    more than ``max_cells`` cells."""
    notes: list[str] = []
    grid, window = _extended(truth_grid, run_grid)
    check_cells(grid, max_cells, "the grid covering the run and the truth map")
    truth_classes_ext = np.full(grid.shape, UNKNOWN, dtype=np.int8)
    truth_classes_ext[window] = truth_classes
    truth_classes = truth_classes_ext
    run, _ = resample_classes(run_classes, run_grid, grid)
    outside_mask = np.ones(grid.shape, dtype=bool)
    outside_mask[window] = False
    truth_grid = grid
    res = truth_grid.resolution
    t_occ = truth_classes == OCCUPIED
    t_known = truth_classes != UNKNOWN
    # The walls scored: both maps' occupied cells outside true solids, as one-cell lines.
    inside = interior(t_occ)
    r_wall = thin((run == OCCUPIED) & ~inside)
    t_wall = thin(t_occ & ~inside)
    outside = int((outside_mask & r_wall).sum())
    if outside:
        notes.append(f"{outside} run wall cell(s) lie outside the truth map (counted in "
                     "precision: no true wall there)")

    if poses_xy is not None and reach_m is not None:
        scope = _in_reach(truth_grid, poses_xy, reach_m)
        recall_scope = "within_reach"
    else:
        scope = np.ones(truth_grid.shape, dtype=bool)
        recall_scope = "all"
        why = "no trajectory" if poses_xy is None else "no known sensor reach"
        notes.append(f"{why}: recall and unknown fraction are over all true cells")

    # Precision from a largest matching into all true walls, recall from one into those in
    # scope: one matching attains both (the true cells a matching can cover form a matroid,
    # so a largest matching into the walls in scope extends to a largest one into all).
    r_matched, t_matched = match(r_wall, t_wall, tolerance_m, res)
    run_occupied = int(r_wall.sum())
    run_matched = int(r_matched.sum())
    t_scope = t_wall & scope
    if not scope.all():
        _, t_matched = match(r_wall, t_scope, tolerance_m, res)
    truth_in_scope = int(t_scope.sum())
    truth_matched = int((t_matched & scope).sum())
    precision = _ratio(run_matched, run_occupied)
    recall = _ratio(truth_matched, truth_in_scope)
    if precision is None:
        notes.append("the run has no occupied cells on the truth map: precision undefined, 0")
    if recall is None:
        notes.append("no true occupied cells in scope: recall undefined, 0")
    p, r = precision or 0.0, recall or 0.0
    f1 = 0.0 if p + r == 0 else 2.0 * p * r / (p + r)

    r_free = (run == FREE) & t_known
    run_free = int(r_free.sum())
    run_free_correct = int((r_free & (truth_classes == FREE)).sum())
    k_scope = t_known & scope
    known_in_scope = int(k_scope.sum())
    unknown_in_scope = int((k_scope & (run == UNKNOWN)).sum())

    dist_run = _distance_to(r_wall, res)
    false_occupied, missed = error_breakdown(
        r_wall & ~r_matched, t_scope & ~t_matched, run, truth_classes,
        _distance_to(t_wall, res), dist_run, tolerance_m,
    )
    oblique: dict[str, float] = {}
    if oblique_deg is not None and poses_xy is not None and reach_m is not None:
        from pipeline.tools.oblique_walls import seen_obliquely

        obl = seen_obliquely(t_occ, truth_grid, t_scope, poses_xy, reach_m, oblique_deg)
        miss = t_scope & ~t_matched
        free_miss = miss & ~_within(dist_run, NEAR_M) & (run == FREE)
        oblique = {"incidence_deg": float(oblique_deg), "walls": int(obl.sum()),
                   "missed": int((obl & miss).sum()),
                   "missed_seen_free": int((obl & free_miss).sum())}
    mean_d: float | None = None
    median_d: float | None = None
    if feature_xy.shape[0] and t_occ.any():
        from scipy.spatial import cKDTree

        rr, cc = np.nonzero(t_occ)
        centres = np.column_stack([
            truth_grid.origin_x + (cc + 0.5) * res, truth_grid.origin_y + (rr + 0.5) * res
        ])
        d, _ = cKDTree(centres).query(feature_xy, k=1)
        mean_d, median_d = float(np.mean(d)), float(np.median(d))
    elif feature_xy.shape[0] == 0:
        notes.append("the run has no features: no feature distance")
    else:
        notes.append("the truth has no occupied cells: no feature distance")

    values = {
        "tolerance_m": float(tolerance_m),
        "reach_m": reach_m,
        "recall_scope": recall_scope,
        "precision": float(p),
        "recall": float(r),
        "f1": float(f1),
        "free_accuracy": _ratio(run_free_correct, run_free),
        "unknown_fraction": _ratio(unknown_in_scope, known_in_scope),
        "run_occupied": run_occupied,
        "run_occupied_matched": run_matched,
        "run_occupied_outside": outside,
        "truth_occupied_in_scope": truth_in_scope,
        "truth_occupied_matched": truth_matched,
        "run_free": run_free,
        "run_free_correct": run_free_correct,
        "truth_known_in_scope": known_in_scope,
        "run_unknown_in_scope": unknown_in_scope,
        "features": int(feature_xy.shape[0]),
        "feature_distance_mean_m": mean_d,
        "feature_distance_median_m": median_d,
        "false_occupied": false_occupied,
        "missed": missed,
        "oblique": oblique,
        "matching": MATCHING,
    }
    return values, tuple(notes)


# A false cell this close to a true wall (or a missed wall cell this close to a predicted
# one) is a placement error, not a phantom or a hole, m.
NEAR_M = 0.25


def error_breakdown(
    false: B, miss: B, run_classes: I8, truth_classes: I8,
    dist_truth: F64, dist_run: F64, tolerance_m: float,
) -> tuple[dict[str, int], dict[str, int]]:
    """Why a map is wrong, in truth-grid cells.

    ``false``: the run's unmatched wall cells; ``miss``: the unmatched true wall cells in
    scope; ``dist_truth`` and ``dist_run``: distances, m, to the nearest true and run wall
    cell. False cells are ``double`` (within ``tolerance_m`` of a true wall whose cells all
    went to other run cells: a second line along a wall), ``near_wall`` (farther, within
    ``NEAR_M``: a wall drawn in the wrong place), ``in_free_space`` (farther, where the
    truth is free: a phantom inside the rooms, which the run should have seen free) or
    ``unobserved`` (farther, where the truth is unknown: behind walls or outside the
    building). Missed wall cells are ``near_prediction`` (a run wall cell within
    ``NEAR_M``), ``seen_free`` (the run calls the cell free: free-space evidence overrode
    the wall) or ``unobserved`` (the run left it unknown).
    """
    close = _within(dist_truth, tolerance_m)
    near = _within(dist_truth, NEAR_M) & ~close
    far = ~close & ~near
    near_pred = _within(dist_run, NEAR_M)
    false_occupied = {
        "double": int((false & close).sum()),
        "near_wall": int((false & near).sum()),
        "in_free_space": int((false & far & (truth_classes == FREE)).sum()),
        "unobserved": int((false & far & (truth_classes == UNKNOWN)).sum()),
    }
    missed = {
        "near_prediction": int((miss & near_pred).sum()),
        "seen_free": int((miss & ~near_pred & (run_classes == FREE)).sum()),
        "unobserved": int((miss & ~near_pred & (run_classes == UNKNOWN)).sum()),
    }
    return false_occupied, missed


def evaluate_run(
    run_dir: str | Path,
    truth_yaml: str | Path,
    *,
    trajectory: str | Path | None = None,
    tolerance_m: float = 0.10,
    sensor_reach_m: float | None = None,
    truth_trajectory: str | Path | None = None,
    rpe_delta: float = 1.0,
    rpe_unit: str = "m",
    oblique_deg: float | None = None,
) -> Evaluation:
    """Score the run in ``run_dir`` against the nav2 ground-truth map ``truth_yaml``.

    ``trajectory``: CSV ``t,x,y,yaw`` of the true poses (the simulator's
    ``<stem>.truth.csv``); recall counts only true occupied cells within the sensor reach
    of it. ``sensor_reach_m`` overrides the run's own largest sensor range (m).
    ``truth_trajectory``: CSV of the true poses; adds the ATE and RPE (per ``rpe_delta``
    ``rpe_unit``) of the run's ``trajectory.csv`` against it (:mod:`pipeline.tools.trajectory_error`).
    ``oblique_deg`` (with ``trajectory``): count the true walls the path mostly saw more
    than this many degrees off their normal (:mod:`pipeline.tools.oblique_walls`).
    InputError for a run directory missing files, FormatError for unreadable ones.
    """
    from formats.writers.features_parquet import read_features
    from formats.writers.nav2_map import load_nav2_map

    run_dir = Path(run_dir)
    truth_yaml = Path(truth_yaml)
    if not (math.isfinite(tolerance_m) and tolerance_m >= 0):
        raise ConfigError(f"tolerance must be a finite number >= 0 m, got {tolerance_m!r}")
    if sensor_reach_m is not None and not (math.isfinite(sensor_reach_m) and sensor_reach_m > 0):
        raise ConfigError(f"sensor reach must be a finite number > 0 m, got {sensor_reach_m!r}")
    if not run_dir.is_dir():
        raise InputError("run directory not found", run_dir)
    missing = [f for f in RUN_FILES if not (run_dir / f).is_file()]
    if missing:
        raise InputError(f"not a complete run directory: missing {', '.join(missing)}", run_dir)

    metrics = read_metrics(run_dir / "metrics.json")
    max_cells = run_max_cells(run_dir)
    run_map = load_nav2_map(run_dir / "map.yaml", max_cells)
    truth = load_nav2_map(truth_yaml, max_cells)
    features = read_features(run_dir / "features.parquet")
    reach: float | None
    if sensor_reach_m is not None:
        reach, reach_source = float(sensor_reach_m), "argument"
    else:
        reach, reach_source = run_sensor_reach(run_dir, metrics)
    poses = None if trajectory is None else read_trajectory(Path(trajectory)).xy

    values, notes = evaluate_maps(
        run_map.classes, run_map.grid, truth.classes, truth.grid,
        tolerance_m=tolerance_m, poses_xy=poses, reach_m=reach,
        feature_xy=np.column_stack([features.x, features.y]), max_cells=max_cells,
        oblique_deg=oblique_deg,
    )
    traj_err = aligned = None
    if truth_trajectory is not None:
        traj_err = _trajectory_error(run_dir, Path(truth_trajectory), rpe_delta, rpe_unit)
        motion = (float(traj_err["alignment"][0]), float(traj_err["alignment"][1]),
                  float(traj_err["alignment"][2]))
        moved, moved_grid = move_classes(run_map.classes, run_map.grid, motion, max_cells)
        fx, fy = transform_points(motion, features.x, features.y)
        scores, _ = evaluate_maps(
            moved, moved_grid, truth.classes, truth.grid, tolerance_m=tolerance_m,
            poses_xy=poses, reach_m=reach, feature_xy=np.column_stack([fx, fy]),
            max_cells=max_cells,
        )
        aligned = {"precision": scores["precision"], "recall": scores["recall"],
                   "f1": scores["f1"], "alignment": list(motion)}
    mean_var = finite(metrics.get("paper_metric", {}).get("mean_feature_variance_m2"))
    if mean_var is None:
        notes += ("metrics.json has no mean feature variance",)
    return Evaluation(
        run_dir=str(run_dir),
        truth=str(truth_yaml),
        trajectory=None if trajectory is None else str(trajectory),
        reach_source=reach_source,
        mean_feature_variance_m2=mean_var,
        notes=notes,
        trajectory_error=traj_err,
        aligned=aligned,
        **values,
    )


def _trajectory_error(
    run_dir: Path, truth_path: Path, rpe_delta: float, rpe_unit: str
) -> dict[str, Any]:
    """ATE/RPE of the run's trajectory.csv against the true trajectory CSV."""
    from pipeline.tools.trajectory_error import trajectory_error

    run_traj = run_dir / "trajectory.csv"
    if not run_traj.is_file():
        raise InputError("run directory has no trajectory.csv (written by sonarmap run)", run_dir)
    est = read_trajectory(run_traj)
    truth = read_trajectory(truth_path)
    if rpe_unit not in ("m", "frames"):
        raise ConfigError(f"RPE unit must be 'm' or 'frames', got {rpe_unit!r}")
    try:
        result = trajectory_error(
            est, truth, rpe_delta=rpe_delta, rpe_unit="m" if rpe_unit == "m" else "frames",
        )
    except InputError as err:
        raise InputError(err.reason, truth_path) from err
    return result.to_dict()
