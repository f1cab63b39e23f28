"""Run metrics: what went in, what happened, what came out — as one JSON-ready object.

``RunMetrics.deterministic()`` is everything that depends only on the input and the
configuration (byte-identical across reruns); ``timing`` (stage seconds, readings/s, peak
RSS) is kept apart in its own section so reruns can be compared with it removed.
"""

from __future__ import annotations

import hashlib
import json
import resource
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formats.storage.location import Location, Url
from pipeline.mapper.types import MapSnapshot


class StageTimer:
    """Wall seconds per named stage; a stage may be entered many times (streaming)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0


def peak_rss_mb() -> float:
    """Peak resident set size of this process, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def sha256_of(path: Location) -> str:
    """sha256 of a file, or of a directory's files (sorted relative names and contents);
    the same for a URL (object, or prefix) holding the same bytes."""
    h = hashlib.sha256()
    is_dir = path.is_dir()
    files: list[Location] = []
    if isinstance(path, Url):
        files = [f for f in path.rglob("*") if f.name] if is_dir else [path]
    else:
        files = [*sorted(p for p in path.rglob("*") if p.is_file())] if is_dir else [path]
    for f in files:
        if is_dir:
            rel = f.relative_to(path)  # type: ignore[arg-type]
            h.update(str(rel).encode() + b"\0")
        with f.open("rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def map_cells(snapshot: MapSnapshot, occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> dict[str, Any]:
    """Occupied/free/unknown cell counts with the nav2 thresholds, and mapped area (m²)."""
    p = snapshot.probability
    known = ~np.isnan(p)
    occ = int((known & (p > occupied_thresh)).sum())
    free = int((known & (p < free_thresh)).sum())
    total = int(p.size)
    res = snapshot.grid.resolution
    return {
        "width": snapshot.grid.width,
        "height": snapshot.grid.height,
        "resolution_m": res,
        "origin": [snapshot.grid.origin_x, snapshot.grid.origin_y, 0.0],
        "cells_total": total,
        "cells_occupied": occ,
        "cells_free": free,
        "cells_unknown": total - occ - free,
        "mapped_area_m2": round((occ + free) * res * res, 6),
    }


@dataclass
class RunMetrics:
    """Everything metrics.json holds."""

    input: dict[str, Any]
    counts: dict[str, Any]
    dropped: dict[str, int]
    paper_metric: dict[str, Any]
    map: dict[str, Any]
    trajectory: dict[str, Any]
    sensors: list[dict[str, Any]]
    run: dict[str, Any]
    timing: dict[str, Any] = field(default_factory=dict)
    comparison: dict[str, Any] | None = None
    pose_refinement: dict[str, Any] | None = None  # run --refine-poses (pipeline/refine/)
    warnings: list[str] = field(default_factory=list)

    def deterministic(self) -> dict[str, Any]:
        out = {
            "input": self.input,
            "run": self.run,
            "counts": self.counts,
            "dropped": self.dropped,
            "paper_metric": self.paper_metric,
            "map": self.map,
            "trajectory": self.trajectory,
            "sensors": self.sensors,
        }
        if self.comparison is not None:
            out["comparison"] = self.comparison
        if self.pose_refinement is not None:
            out["pose_refinement"] = self.pose_refinement
        out["warnings"] = self.warnings
        return out

    def to_dict(self) -> dict[str, Any]:
        return {**self.deterministic(), "timing": self.timing}

    def to_json(self) -> str:
        return json.dumps(_clean(self.to_dict()), indent=2, sort_keys=False) + "\n"


def json_ready(v: Any) -> Any:
    """``v`` with NaN/Inf as null, numpy scalars as Python numbers (what metrics.json holds)."""
    return _clean(v)


def _clean(v: Any) -> Any:
    """JSON has no NaN/Inf: write them as null. Round floats for stable text."""
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return None if not np.isfinite(f) else float(f"{f:.12g}")
    if isinstance(v, np.integer):
        return int(v)
    return v
