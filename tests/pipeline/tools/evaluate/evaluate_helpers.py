"""Hand-built truth maps and run directories for the evaluate/regress tests.

The truth is 4 m × 3 m at 0.05 m (80 × 60 cells, origin (0, 0)) with one straight wall on
row 30 (y ∈ [1.50, 1.55), centre y = 1.525) from column 10 to 69 (x centres 0.525 … 3.475):
60 occupied cells, every other cell free.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from formats.map_types import FeatureTable, GridSpec
from formats.writers.features_parquet import write_features
from formats.writers.nav2_map import write_nav2_map

TRUTH_GRID = GridSpec(0.0, 0.0, 0.05, 80, 60)
WALL_ROW = 30
WALL_COLS = slice(10, 70)
WALL_CELLS = 60


def wall_probability(grid: GridSpec = TRUTH_GRID, row: int = WALL_ROW,
                     cols: slice = WALL_COLS) -> np.ndarray:
    """Free everywhere (0.0), occupied (1.0) on ``row`` over ``cols``."""
    p = np.zeros(grid.shape, dtype=np.float32)
    p[row, cols] = 1.0
    return p


def write_truth(dir_: Path, name: str = "world") -> Path:
    """The wall world as ``<dir>/<name>.truth.yaml`` (+ .pgm); returns the YAML path."""
    path = dir_ / f"{name}.truth.yaml"
    write_nav2_map(path, wall_probability(), TRUTH_GRID)
    return path


def features_at(xy: list[tuple[float, float]], var: float = 0.01) -> FeatureTable:
    n = len(xy)
    arr = np.array(xy, dtype=np.float64).reshape(n, 2)
    ints = np.arange(n, dtype=np.int64)
    return FeatureTable(
        id=ints, x=arr[:, 0].copy(), y=arr[:, 1].copy(),
        cov_xx=np.full(n, var), cov_xy=np.zeros(n), cov_yy=np.full(n, var),
        measured_times=np.ones(n, dtype=np.int64), first_seen_ns=ints, last_seen_ns=ints,
        merges=np.zeros(n, dtype=np.int64),
    )


def metrics_doc(*, features: int = 3, readings_used: int = 1000,
                mean_var: float | None = 0.0123, sha: str = "abc") -> dict[str, Any]:
    """The parts of metrics.json evaluate and regress read."""
    return {
        "input": {"name": "world.mcap", "sha256": sha},
        "run": {"method": "andersone", "config_hash": "0123456789abcdef"},
        "counts": {"readings": 1200, "readings_used": readings_used, "features": features},
        "paper_metric": {"mean_feature_variance_m2": mean_var, "features": features},
        "sensors": [{"name": "sonar_0", "readings": 1200}],
    }


def write_run(
    dir_: Path,
    probability: np.ndarray | None = None,
    grid: GridSpec = TRUTH_GRID,
    *,
    features: FeatureTable | None = None,
    metrics: dict[str, Any] | None = None,
    config_toml: str | None = None,
) -> Path:
    """A run directory as pipeline.run writes it (the files evaluate and regress read)."""
    dir_.mkdir(parents=True, exist_ok=True)
    prob = wall_probability() if probability is None else probability
    write_nav2_map(dir_ / "map.yaml", prob, grid)
    feats = features if features is not None else features_at(
        [(2.025, 1.525), (2.025, 1.825), (3.875, 1.525)]
    )
    write_features(dir_ / "features.parquet", feats, metadata={"method": "andersone"})
    doc = metrics if metrics is not None else metrics_doc(features=len(feats))
    (dir_ / "metrics.json").write_text(json.dumps(doc, indent=2), encoding="utf-8")
    if config_toml is not None:
        (dir_ / "config.toml").write_text(config_toml, encoding="utf-8")
    return dir_


def shifted_wall(rows: int) -> np.ndarray:
    """The truth wall moved ``rows`` cells up (+y)."""
    return wall_probability(row=WALL_ROW + rows)
