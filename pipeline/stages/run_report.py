"""A run directory's reports, rendered from the run's own files.

``sonarmap run`` renders them once its metrics.json and feature table are written;
``sonarmap evaluate`` renders them again with the evaluation added. Both read the same
files the same way, so the report a run writes is the report evaluate rewrites, plus the
evaluation.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from formats.writers.features_parquet import read_features
from formats.writers.report import COMPARISON_LABELS, write_reports
from pipeline.stages.metrics_schema import read_metrics

__all__ = ["COMPARISON_IMAGES", "write_run_reports"]

#: The map image of each column of metrics.json ``comparison``.
COMPARISON_IMAGES = {"with_correction": "map.png", "without_correction": "map_no_correction.png"}
#: Further images a run may hold, with their caption in the reports.
FIGURES = {"trajectory.png": "Pose refinement: odometry and refined trajectory"}


def write_run_reports(run_dir: Path, evaluation: Mapping[str, Any] | None = None) -> None:
    """(Re)write ``run_dir/report.html`` and ``report.md`` from metrics.json,
    features.parquet and the map images in ``run_dir``; ``evaluation``: a ``sonarmap
    evaluate`` result (as a dict) to add."""
    run_dir = Path(run_dir)
    metrics = read_metrics(run_dir / "metrics.json")
    metrics.pop("timing", None)  # differs on every rerun: not in the report
    features = read_features(run_dir / "features.parquet")
    comparison = metrics.get("comparison") or {}
    images = {
        COMPARISON_LABELS[key]: run_dir / name
        for key, name in COMPARISON_IMAGES.items()
        if key in comparison
    }
    figures = {caption: run_dir / name for name, caption in FIGURES.items()
               if (run_dir / name).is_file()}
    write_reports(run_dir, metrics=metrics, features=features, map_png=run_dir / "map.png",
                  comparison_pngs=images or None, evaluation=evaluation,
                  figures=figures or None)
