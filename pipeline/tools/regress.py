"""Compare a run directory with a golden run directory: did the map get worse?

``regress(run_dir, golden_dir, tolerances)`` checks, row by row (metric, golden, current,
tolerance, ok):

* ``f1`` — only when the golden directory holds an ``evaluation.json`` (written by
  ``sonarmap evaluate --output`` when the golden was refreshed): the run is re-evaluated
  against the same truth, trajectory, tolerance and reach named in it, and its F1 may not
  drop by more than ``f1_drop`` below the golden's (an improvement always passes); a golden
  scored by another wall-matching rule (its ``matching``) is not compared, with a note.
  Relative paths in evaluation.json are looked up beside the golden directory, then in the
  golden directory's parents (so repository-relative paths work from any checkout), then in
  the working directory.
* ``features`` — ``metrics.json`` ``counts.features`` within ``features_rel`` of the golden
  (relative, both ways; a golden of 0 needs exactly 0).
* ``mean_feature_variance_m2`` — ``paper_metric`` within ``mean_feature_variance_rel``
  (relative, both ways; both missing passes, one missing fails).
* ``map_grid`` — map.yaml size, resolution and origin identical (within 1e-9 m); a
  different grid is a regression and the cells cannot be compared.
* ``map_cells_differing`` — fraction of map cells whose class (occupied/free/unknown, as
  map_server reads map.pgm) differs, at most ``map_cells_differ``.
* ``readings_used`` — ``counts.readings_used`` within ``readings_used_abs`` (default:
  exactly equal).

Tolerances come from a TOML file of flat keys (any subset; the rest keep the defaults
of :class:`Tolerances`); :func:`tolerances_toml` prints the documented defaults.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Literal

import numpy as np

from formats.errors import ConfigError, FormatError, InputError
from formats.options import doc_field
from formats.tables import text_table
from formats.toml_file import read_toml
from pipeline.stages.metrics_schema import Metrics, read_metrics

__all__ = [
    "GOLDEN_EVALUATION",
    "Regression",
    "RegressionRow",
    "Tolerances",
    "load_tolerances",
    "regress",
    "show_value",
    "tolerances_toml",
]

#: The evaluation a golden directory may carry, made when the golden was refreshed.
GOLDEN_EVALUATION = "evaluation.json"

_REQUIRED = ("metrics.json", "map.yaml")


@dataclass(frozen=True)
class Tolerances:
    """How far a run may differ from its golden before it counts as a regression."""

    f1_drop: float = doc_field("F1 may drop by at most this much below the golden's (absolute)", default=0.01)
    features_rel: float = doc_field("feature count within this fraction of the golden's", default=0.02)
    mean_feature_variance_rel: float = doc_field(
        "mean feature variance (m²) within this fraction of the golden's", default=0.05
    )
    map_cells_differ: float = doc_field(
        "at most this fraction of map cells may change class (occupied/free/unknown)", default=0.005
    )
    readings_used_abs: int = doc_field("readings used may differ by at most this many", default=0)


def tolerances_toml(tol: Tolerances | None = None) -> str:
    """``tol`` (default: the defaults) as a commented TOML file for ``--tolerances``."""
    tol = tol or Tolerances()
    lines = ["# sonarmap regress tolerances; every key is optional (defaults shown)."]
    for f in fields(tol):
        lines += [f"# {f.metadata['doc']}", f"{f.name} = {getattr(tol, f.name)!r}"]
    return "\n".join(lines) + "\n"


def load_tolerances(path: str | Path | None) -> Tolerances:
    """Tolerances from a TOML file (``None``: the defaults); ConfigError naming the file."""
    if path is None:
        return Tolerances()
    p = Path(path)
    data = read_toml(p, "tolerances")
    known = {f.name: f for f in fields(Tolerances)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ConfigError(
            f"unknown key '{unknown[0]}' (known: {', '.join(sorted(known))})", p
        )
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        want_int = key == "readings_used_abs"
        ok_type = isinstance(value, int) if want_int else isinstance(value, int | float)
        if isinstance(value, bool) or not ok_type:
            what = "an integer" if want_int else "a number"
            raise ConfigError(f"'{key}' must be {what}, got {value!r}", p)
        if not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"'{key}' must be >= 0, got {value!r}", p)
        kwargs[key] = value if want_int else float(value)
    return Tolerances(**kwargs)


@dataclass(frozen=True)
class RegressionRow:
    """One compared metric: ``ok`` False means it regressed."""

    metric: str
    golden: Any
    current: Any
    tolerance: str
    ok: bool
    detail: str = ""


@dataclass(frozen=True)
class Regression:
    """The rows of one run-versus-golden comparison; ``ok`` when no row regressed."""

    run_dir: str
    golden_dir: str
    rows: tuple[RegressionRow, ...]
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return all(r.ok for r in self.rows)

    @property
    def failed(self) -> tuple[RegressionRow, ...]:
        return tuple(r for r in self.rows if not r.ok)

    def to_dict(self) -> dict[str, Any]:
        return {
            "run_dir": self.run_dir,
            "golden_dir": self.golden_dir,
            "ok": self.ok,
            "rows": [
                {f.name: _plain(getattr(r, f.name)) for f in fields(RegressionRow)}
                for r in self.rows
            ],
            "notes": list(self.notes),
        }

    def format_table(self, *, failed_only: bool = False) -> str:
        """A text table of every row (or only the regressed ones), then the notes."""
        rows = self.failed if failed_only else self.rows
        head = ("metric", "golden", "current", "tolerance", "status")
        body = [
            (r.metric, show_value(r.golden), show_value(r.current), r.tolerance,
             ("ok" if r.ok else "REGRESSED") + (f" ({r.detail})" if r.detail else ""))
            for r in rows
        ]
        lines = text_table(head, body, rule=True)
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def _plain(v: Any) -> Any:
    if isinstance(v, float):
        return float(f"{v:.12g}") if math.isfinite(v) else None
    return v


def show_value(v: Any) -> str:
    """A compared value as tables print it (``n/a`` for none, 6 significant digits)."""
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


# --------------------------------------------------------------------------- comparisons


def _count(doc: Metrics, key: Literal["features", "readings_used"], path: Path) -> int:
    counts = doc.get("counts", {})
    if key not in counts:
        raise FormatError(f"metrics have no counts.{key}", path)
    return counts[key]


def _variance(doc: Metrics, path: Path) -> float | None:
    paper = doc.get("paper_metric", {})
    if "mean_feature_variance_m2" not in paper:
        raise FormatError("metrics have no paper_metric.mean_feature_variance_m2", path)
    v = paper["mean_feature_variance_m2"]
    return None if v is None else float(v)


def _relative_row(
    metric: str, golden: float | None, current: float | None, rel: float
) -> RegressionRow:
    tol = f"±{100.0 * rel:g} %"
    if golden is None or current is None:
        ok = golden is None and current is None
        return RegressionRow(metric, golden, current, tol, ok, "" if ok else "missing on one side")
    diff = abs(current - golden)
    ok = diff <= rel * abs(golden) * (1.0 + 1e-12)
    detail = "" if golden == 0 else f"{100.0 * (current - golden) / abs(golden):+.2f} %"
    return RegressionRow(metric, golden, current, tol, ok, detail)


def _compare_maps(run_yaml: Path, golden_yaml: Path, tol: Tolerances) -> list[RegressionRow]:
    from formats.writers.nav2_map import load_nav2_map
    from pipeline.tools.evaluate import run_max_cells

    # Each map within its own run's [grid] max_cells (checked before its image is read).
    run = load_nav2_map(run_yaml, run_max_cells(run_yaml.parent))
    gold = load_nav2_map(golden_yaml, run_max_cells(golden_yaml.parent))
    g, c = gold.grid, run.grid

    def describe(grid: Any) -> str:
        return (f"{grid.width}x{grid.height} @ {grid.resolution:g} m, origin "
                f"({grid.origin_x:g}, {grid.origin_y:g})")

    same = (
        g.shape == c.shape
        and math.isclose(g.resolution, c.resolution, rel_tol=0, abs_tol=1e-9)
        and math.isclose(g.origin_x, c.origin_x, rel_tol=0, abs_tol=1e-9)
        and math.isclose(g.origin_y, c.origin_y, rel_tol=0, abs_tol=1e-9)
    )
    rows = [RegressionRow("map_grid", describe(g), describe(c), "identical", same)]
    limit = f"≤ {100.0 * tol.map_cells_differ:g} % of cells"
    if not same:
        rows.append(RegressionRow("map_cells_differing", 0.0, None, limit, False,
                                  "grids differ, cells not comparable"))
        return rows
    differing = int(np.count_nonzero(run.classes != gold.classes))
    frac = differing / max(run.classes.size, 1)
    ok = frac <= tol.map_cells_differ * (1.0 + 1e-12)
    rows.append(RegressionRow("map_cells_differing", 0.0, frac, limit, ok,
                              f"{differing} of {run.classes.size} cells"))
    return rows


def _resolve(text: str, golden_dir: Path) -> Path:
    """A path named in a golden's evaluation.json; see the module docstring for the order."""
    p = Path(text)
    if p.is_absolute():
        return p
    for base in (golden_dir, *golden_dir.resolve().parents, Path.cwd()):
        if (base / p).exists():
            return base / p
    return p


def _f1_row(
    run_dir: Path, golden_dir: Path, tol: Tolerances, notes: list[str],
    truth_files: tuple[Path, Path | None] | None = None,
) -> RegressionRow | None:
    from pipeline.tools.evaluate import Evaluation, evaluate_run

    path = golden_dir / GOLDEN_EVALUATION
    if not path.is_file():
        notes.append(f"golden has no {GOLDEN_EVALUATION}: F1 not compared")
        return None
    import json

    from formats.text_file import read_text

    try:
        doc = json.loads(read_text(path, "golden evaluation", errors=(FormatError, FormatError)))
    except (json.JSONDecodeError, RecursionError) as err:
        raise FormatError(f"cannot read golden evaluation: {err}", path) from err
    golden = Evaluation.from_dict(doc, path)
    if truth_files is not None:
        truth, named_traj = truth_files
    else:
        truth = _resolve(golden.truth, golden_dir)
        named_traj = _resolve(golden.trajectory, golden_dir) if golden.trajectory else None
    if not truth.exists():
        raise InputError(f"golden evaluation names a truth map that is not found: {truth}", path)
    # The golden's own scope: its reach, or no trajectory when it scored all true cells.
    within = golden.recall_scope == "within_reach" and golden.trajectory is not None
    traj = named_traj if within else None
    current = evaluate_run(
        run_dir, truth, trajectory=traj, tolerance_m=golden.tolerance_m,
        sensor_reach_m=golden.reach_m if within else None,
    )
    if current.matching != golden.matching:
        notes.append(f"golden F1 was scored by '{golden.matching}', evaluate now scores by "
                     f"'{current.matching}': F1 not compared (refresh the golden)")
        return None
    # evaluation.json holds 12 significant digits: compare the current F1 at that precision.
    f1 = float(f"{current.f1:.12g}")
    ok = f1 >= golden.f1 - tol.f1_drop - 1e-12
    return RegressionRow("f1", golden.f1, f1, f"drop ≤ {tol.f1_drop:g}", ok,
                         f"{f1 - golden.f1:+.4f}")


def regress(
    run_dir: str | Path, golden_dir: str | Path, tolerances: Tolerances | None = None,
    *, truth_files: tuple[Path, Path | None] | None = None,
) -> Regression:
    """Compare ``run_dir`` with ``golden_dir`` (same layout); see the module docstring.

    ``truth_files``: (truth map, true trajectory or None) to score F1 with instead of the
    paths the golden's evaluation.json names (a suite names them itself).

    InputError when either directory lacks metrics.json or map.yaml; FormatError when a
    file is unreadable.
    """
    run_dir, golden_dir = Path(run_dir), Path(golden_dir)
    tol = tolerances or Tolerances()
    for d, what in ((run_dir, "run"), (golden_dir, "golden")):
        if not d.is_dir():
            raise InputError(f"{what} directory not found", d)
        missing = [f for f in _REQUIRED if not (d / f).is_file()]
        if missing:
            raise InputError(f"not a complete {what} directory: missing {', '.join(missing)}", d)
    cur_path, gold_path = run_dir / "metrics.json", golden_dir / "metrics.json"
    cur, gold = read_metrics(cur_path), read_metrics(gold_path)
    notes: list[str] = []
    rows: list[RegressionRow] = []

    f1 = _f1_row(run_dir, golden_dir, tol, notes, truth_files)
    if f1 is not None:
        rows.append(f1)
    g_feat = _count(gold, "features", gold_path)
    c_feat = _count(cur, "features", cur_path)
    rows.append(_relative_row("features", g_feat, c_feat, tol.features_rel))
    rows.append(_relative_row("mean_feature_variance_m2", _variance(gold, gold_path),
                              _variance(cur, cur_path), tol.mean_feature_variance_rel))
    rows += _compare_maps(run_dir / "map.yaml", golden_dir / "map.yaml", tol)
    g_used = _count(gold, "readings_used", gold_path)
    c_used = _count(cur, "readings_used", cur_path)
    rows.append(RegressionRow(
        "readings_used", g_used, c_used,
        "exact" if tol.readings_used_abs == 0 else f"±{tol.readings_used_abs}",
        abs(c_used - g_used) <= tol.readings_used_abs,
        "" if c_used == g_used else f"{c_used - g_used:+d}",
    ))

    # Context, not verdicts: a different input or configuration explains a regression.
    if gold.get("input", {}).get("sha256") != cur.get("input", {}).get("sha256"):
        notes.append("input log differs from the golden's (input.sha256)")
    if gold.get("run", {}).get("config_hash") != cur.get("run", {}).get("config_hash"):
        notes.append("configuration differs from the golden's (run.config_hash)")
    return Regression(str(run_dir), str(golden_dir), tuple(rows), tuple(notes))
