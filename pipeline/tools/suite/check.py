"""One log of a suite, on a worker: map it, then compare it with its golden or stage the
new golden; never raises.

:func:`check_log` maps the log as ``sonarmap run`` would into ``work/<name>/run`` (one
mapper thread: the workers share the cores; no result depends on it), then

* comparing: :func:`pipeline.tools.regress.regress` against the golden, F1 scored with the
  suite's own truth; with a diff directory, a log whose map changed gets
  ``<name>.png`` (:mod:`formats.writers.map_diff_png`);
* updating: the new golden staged in ``work/<name>/golden``
  (:func:`.golden_dir.stage_golden`) and, against an existing golden, what moved (the
  compared values that differ). The driver puts it in place.

Paths recorded in goldens (``metrics.json`` input, ``evaluation.json`` truth and run
directory) are as the driver gives them: relative to its working directory when inside it.
"""

from __future__ import annotations

import os
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from formats.errors import SonarmapError

__all__ = ["CheckJob", "CheckResult", "check_log"]


@dataclass(frozen=True)
class CheckJob:
    """What a worker needs for one log (plain values: it travels to a Dask worker)."""

    name: str
    paths: tuple[str, ...]
    config: dict[str, Any]  # the log's configuration as the suite gives it
    golden_dir: str  # as evaluation.json records it
    work_dir: str
    tolerances: dict[str, Any]
    update: bool = False
    truth: str | None = None
    truth_trajectory: str | None = None
    diff_png: str | None = None
    cwd: str = ""  # the driver's working directory: relative paths are relative to it


@dataclass
class CheckResult:
    """What happened to one log.

    ``status``: ``ok`` / ``regressed`` (compared), ``new`` / ``updated`` / ``unchanged``
    (staged for an update; the driver decides between updated and unchanged), ``error``
    (could not run or compare: ``reason``). ``rows`` are RegressionRow values as dicts.
    """

    name: str
    status: str
    reason: str = ""
    rows: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0
    staged: str | None = None
    diff_png: str | None = None
    error_type: str = ""
    summary: dict[str, Any] = field(default_factory=dict)  # features, f1, cells changed

    @property
    def failed_rows(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if not r["ok"]]


def _here(text: str, cwd: str) -> Path:
    """A path the driver named: as it is when this process shares its working directory."""
    p = Path(text)
    if p.is_absolute() or not cwd or os.getcwd() == cwd:
        return p
    return Path(cwd) / p


def check_log(job: CheckJob) -> CheckResult:
    """Map, compare or stage one log; every failure is the result's ``reason``."""
    t0 = time.perf_counter()
    try:
        result = _check(job)
    except SonarmapError as err:
        result = CheckResult(job.name, "error", str(err), error_type=type(err).__name__)
    except Exception as err:  # a bug or an unforeseen library error: this row, not the suite
        text = " ".join(f"{type(err).__name__}: {err}".split())
        result = CheckResult(job.name, "error", text, error_type=type(err).__name__,
                             notes=[traceback.format_exc()])
    result.seconds = time.perf_counter() - t0
    return result


def _check(job: CheckJob) -> CheckResult:
    import dataclasses

    from pipeline.config import config_from_dict
    from pipeline.run import run
    from pipeline.tools.regress import Tolerances, regress

    cfg = config_from_dict(job.config)
    fast = cfg.replace(mapper=dataclasses.replace(cfg.mapper, threads=1))
    paths = [_here(p, job.cwd) for p in job.paths]
    work = Path(job.work_dir) / job.name
    run_dir = work / "run"
    run(paths[0] if len(paths) == 1 else paths, run_dir, fast)
    golden = _here(job.golden_dir, job.cwd)
    tol = Tolerances(**job.tolerances)
    truth = None if job.truth is None else _here(job.truth, job.cwd)
    traj = None if job.truth_trajectory is None else _here(job.truth_trajectory, job.cwd)
    truth_files = None if truth is None else (truth, traj)
    if job.update:
        return _stage(job, cfg, run_dir, work / "golden", golden, truth, traj)
    result = regress(run_dir, golden, tol, truth_files=truth_files)
    rows = list(result.to_dict()["rows"])
    out = CheckResult(job.name, "ok" if result.ok else "regressed", rows=rows,
                      notes=list(result.notes), summary=_summary(rows))
    if job.diff_png is not None and _map_changed(rows):
        from formats.writers.map_diff_png import write_map_diff_png

        write_map_diff_png(Path(job.diff_png), golden / "map.yaml", run_dir / "map.yaml",
                           trajectory_csv=run_dir / "trajectory.csv", title=job.name)
        out.diff_png = job.diff_png
    return out


def _map_changed(rows: list[dict[str, Any]]) -> bool:
    for r in rows:
        if r["metric"] == "map_grid" and not r["ok"]:
            return True
        if r["metric"] == "map_cells_differing" and r["current"] not in (0, 0.0):
            return True
    return False


def _moved(row: dict[str, Any]) -> bool:
    """Whether a compared value differs between the old golden and the new run."""
    if row["metric"] == "map_cells_differing":
        return row["current"] not in (0, 0.0)
    return bool(row["golden"] != row["current"])


def _summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    by = {r["metric"]: r for r in rows}
    return {
        "features": by.get("features", {}).get("current"),
        "f1": by.get("f1", {}).get("current"),
        "cells_changed": by.get("map_cells_differing", {}).get("detail", ""),
    }


def _stage(job: CheckJob, cfg: Any, run_dir: Path, staged: Path, golden: Path,
           truth: Path | None, traj: Path | None) -> CheckResult:
    from pipeline.config import dump_config
    from pipeline.tools.evaluate import evaluate_run
    from pipeline.tools.regress import Tolerances, regress
    from pipeline.tools.suite.golden_dir import stage_golden

    evaluation = None
    if truth is not None:
        evaluation = evaluate_run(run_dir, truth, trajectory=traj).to_dict()
        # The paths as the driver names them (as `sonarmap evaluate` run there records them).
        evaluation |= {"run_dir": job.golden_dir, "truth": job.truth,
                       "trajectory": job.truth_trajectory}
    stage_golden(run_dir, staged, dump_config(cfg), evaluation)
    out = CheckResult(job.name, "new", staged=str(staged))
    if (golden / "metrics.json").is_file():
        # What moved: the compared values, golden (old) against current (new).
        try:
            before = regress(run_dir, golden, Tolerances(),
                             truth_files=None if truth is None else (truth, traj))
        except SonarmapError as err:
            out.notes.append(f"old golden not compared: {err}")
        else:
            out.rows = [r for r in before.to_dict()["rows"] if _moved(r)]
        out.status = "updated"
    return out
