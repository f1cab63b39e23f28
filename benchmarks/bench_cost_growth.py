"""How the default method's cost grows: CPU ms per 32-reading scan against grid resolution,
beam width and feature density, split into the paper's mapper inside it and attribution's own
loops; the classic grid beside.

Usage: ``python -m benchmarks.bench_cost_growth [--firings 3000] [--repeat 3]``

Input: the first ``--firings`` ring firings of the mapper benchmark's synthetic room
(:mod:`pipeline.mapper.synthetic`), two per scan. CPU seconds (``time.process_time``), best
of ``--repeat``; "paper's mapper" is the time spent in
:class:`~pipeline.mapper.andersone.AndersoneMapper`'s ``prepare``, ``add_free_space`` and
``integrate_prepared`` (the parts of ``integrate_group``) during the same runs (the default
method runs it in its first pass for ``features.parquet``; inline, ``threads = 1``, so that
process CPU time splits between the two; ``prepare`` also counts §9's free cones from its
spans, a small part of attribution's own work). Prints a Markdown table
(benchmarks/RESULTS.md, "How the cost grows").
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.bench_mapper import group_scans
from formats.map_types import GridSpec
from pipeline.config import MapperConfig
from pipeline.mapper import make_mapper
from pipeline.mapper.andersone import AndersoneMapper
from pipeline.mapper.kernels.warm import warm
from pipeline.mapper.synthetic import ring_scans, room_grid
from pipeline.mapper.types import Scan

# The paper's mapper's steps (integrate_group calls all three; the default method's
# second thread calls them apart).
_PAPER_STEPS = ("prepare", "add_free_space", "integrate_prepared")


def _timed(original: Callable[..., Any], inner: list[float]) -> Callable[..., Any]:
    def timed(self: AndersoneMapper, *args: Any) -> Any:
        c0 = time.process_time()
        try:
            return original(self, *args)
        finally:
            inner[0] += time.process_time() - c0

    return timed


def cpu_per_scan(cfg: MapperConfig, grid: GridSpec, scans: list[Scan], repeat: int,
                 inner: list[float]) -> tuple[float, float, int]:
    """(ms per scan of the whole method, of the paper's mapper inside it, features)."""
    best = (float("inf"), 0.0)
    features = 0
    for _ in range(repeat):
        m = make_mapper(cfg, grid)
        inner[0] = 0.0
        c0 = time.process_time()
        for index in range(m.passes):
            m.begin_pass(index)
            m.integrate_many(scans)
        m.snapshot()
        best = min(best, (time.process_time() - c0, inner[0]))
        features = len(m.feature_table())
    return 1000 * best[0] / len(scans), 1000 * best[1] / len(scans), features


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--firings", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    warm()
    inner = [0.0]
    originals = {name: getattr(AndersoneMapper, name) for name in _PAPER_STEPS}
    for name, original in originals.items():
        setattr(AndersoneMapper, name, _timed(original, inner))
    try:
        _table(args.firings, args.repeat, inner)
    finally:
        for name, original in originals.items():
            setattr(AndersoneMapper, name, original)


def _table(firings: int, repeat: int, inner: list[float]) -> None:
    base = group_scans(ring_scans(firings), 2)
    print(f"load average {os.getloadavg()[0]:.1f}; {len(base)} scans of 32 readings")
    print("| case | default method | paper's mapper inside it | attribution's own | classic "
          "| paper's features |")
    print("|---|---:|---:|---:|---:|---:|")

    def row(label: str, grid: GridSpec, scans: list[Scan], **kw: float) -> None:
        total, paper, features = cpu_per_scan(MapperConfig(method="attribution", threads=1, **kw), grid,
                                              scans, repeat, inner)
        classic, _, _ = cpu_per_scan(MapperConfig(method="classic", **kw), grid, scans,
                                     repeat, inner)
        print(f"| {label} | {total:.2f} | {paper:.2f} | {total - paper:.2f} | {classic:.2f} "
              f"| {features} |", flush=True)

    for res in (0.10, 0.05, 0.025):
        row(f"resolution {res} m", room_grid(res), base)
    for deg in (15, 30, 60):
        wide = [dataclasses.replace(s, fov=np.full_like(s.fov, np.radians(deg))) for s in base]
        row(f"beam {deg} deg", room_grid(0.05), wide)
    for md in (0.30, 0.05):
        row(f"match_distance {md} m", room_grid(0.05), base, match_distance=md)
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
