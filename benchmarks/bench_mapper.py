"""Mapper throughput: readings per second of each method, and of OctoMap for reference.

Usage: ``python benchmarks/bench_mapper.py [--readings N] [--readings-per-scan 32 16]
[--smoke] [--profile]``

Input (deterministic): the synthetic room of :mod:`pipeline.mapper.synthetic` — a 16-sonar
ring (30° beams, 0.1-5 m) driving a loop, ranges by ray casting (first echo in the cone),
0.05 m grid; ring firings are grouped ``k/16`` per scan (32 = the pipeline's default 0.2 s
window = 2 firings; the headline figure). OctoMap (``octomap-python``) inserts each sonar
cone as a fan of rays one cell apart at the echo distance with ``insertPointCloud``
(max-range readings skipped, as the mappers do by default). Prints readings/s, the ratio
to OctoMap, and the §7 mean feature variance with/without correction and split guard.

Figures: see ``benchmarks/RESULTS.md`` (``python -m benchmarks`` runs this at 32/scan
beside the other benchmarks). Timed runs follow a warm-up, so they load the compiled
kernels as every run but a machine's first does; the one-off compile and the per-process
load are measured apart, in fresh processes with an empty numba cache directory. Wall and
CPU-time ratios are both printed: on a shared machine wall time also measures the other
jobs. 2026-11-29 (load average ~15): full method 19.8x OctoMap in wall time, ~17x per CPU
second; classic ~30x per CPU second.
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import math
import os
import pstats
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from formats.map_types import GridSpec
from pipeline.config import MapperConfig
from pipeline.mapper import Mapper, make_mapper
from pipeline.mapper.kernels.warm import warm
from pipeline.mapper.synthetic import ring_scans, room_grid
from pipeline.mapper.types import Scan

_COMPILE_CHILD = """
import time
t0 = time.perf_counter()
from pipeline.mapper.kernels import warm
t1 = time.perf_counter()
print("IMPORT_S", t1 - t0, "WARM_S", warm.warm())
"""


def compile_seconds() -> dict[str, float]:
    """The kernels' one-off cost, each in a fresh process with an empty numba cache
    directory: compiling them (a machine's first run), then loading them from that cache
    (every later process); plus the import time of the mapper with numba."""
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="bench_numba_cache_") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for label in ("cold", "cached"):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            res = subprocess.run([sys.executable, "-c", _COMPILE_CHILD], env=env, check=True,
                                 capture_output=True, text=True)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            # CPU seconds too: on a shared machine the wall time mostly measures the others.
            out[f"process cpu {label} s"] = (after.ru_utime - before.ru_utime
                                             + after.ru_stime - before.ru_stime)
            words = res.stdout.split()
            out[f"import {label} s"] = float(words[words.index("IMPORT_S") + 1])
            out[f"warm {label} s"] = float(words[words.index("WARM_S") + 1])
    return out


# CPU seconds of the last timed run (run_mapper, run_octomap): on a shared machine wall
# time also measures the other jobs; CPU time measures the work.
LAST_CPU = [0.0]


def run_mapper(cfg: MapperConfig, grid: GridSpec, scans: list[Scan]) -> tuple[float, Mapper]:
    """Seconds to integrate all scans (as the pipeline does: ``integrate_many``) and take
    one snapshot, and the mapper."""
    mapper = make_mapper(cfg, grid)
    t0 = time.perf_counter()
    c0 = time.process_time()
    for index in range(mapper.passes):  # the default method reads the scans twice
        mapper.begin_pass(index)
        mapper.integrate_many(scans)
    mapper.snapshot()
    LAST_CPU[0] = time.process_time() - c0
    return time.perf_counter() - t0, mapper


def group_scans(scans: list[Scan], k: int) -> list[Scan]:
    """Consecutive ring firings joined ``k`` at a time (k = 2: the pipeline's 0.2 s window)."""
    if k == 1:
        return scans
    names = [f.name for f in dataclasses.fields(Scan)]
    return [
        Scan(**{n: np.concatenate([getattr(s, n) for s in scans[i : i + k]]) for n in names})
        for i in range(0, len(scans), k)
    ]


def run_octomap(scans: list[Scan], resolution: float) -> float | None:
    """Seconds for OctoMap to insert every echo cone as a fan of rays; None without octomap."""
    try:
        import octomap
    except ImportError:
        return None
    # Fans are built before timing: only OctoMap's insertion is measured.
    clouds = []
    for s in scans:
        for k in range(len(s)):
            d, r_max = float(s.range_m[k]), float(s.max_range[k])
            if not (math.isfinite(d) and s.min_range[k] <= d < r_max - 0.01):
                continue
            n = max(2, math.ceil(d * float(s.fov[k]) / resolution) + 1)
            ang = s.alpha[k] + np.linspace(-0.5 * s.fov[k], 0.5 * s.fov[k], n)
            pts = np.stack(
                [s.origin_x[k] + d * np.cos(ang), s.origin_y[k] + d * np.sin(ang), np.zeros(n)],
                axis=1,
            )
            origin = np.array([s.origin_x[k], s.origin_y[k], 0.0])
            clouds.append((pts, origin, r_max))
    tree = octomap.OcTree(resolution)
    t0 = time.perf_counter()
    c0 = time.process_time()
    for pts, origin, r_max in clouds:
        tree.insertPointCloud(pts, origin, maxrange=r_max)
    LAST_CPU[0] = time.process_time() - c0
    return time.perf_counter() - t0


METHODS = [
    ("forward (default, §11)", MapperConfig(method="forward")),
    ("specular (§10)", MapperConfig(method="specular")),
    ("attribution", MapperConfig(method="attribution")),
    ("andersone+correction", MapperConfig(method="andersone")),
    ("andersone+correction+split_guard", MapperConfig(method="andersone", split_guard=True)),
    ("andersone", MapperConfig(method="andersone", feature_correction=False)),
    ("classic", MapperConfig(method="classic")),
]


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Run the benchmark, print the tables; returns readings/s per method (and octomap)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readings", type=int, default=100_000, help="approximate readings")
    parser.add_argument(
        "--readings-per-scan", type=int, nargs="+", default=[32, 16],
        help="scan sizes to time, multiples of 16 (32 = the pipeline's 0.2 s window)",
    )
    parser.add_argument("--repeat", type=int, default=1, help="runs per method (best kept)")
    parser.add_argument("--smoke", action="store_true", help="tiny input, a few seconds")
    parser.add_argument("--profile", action="store_true", help="cProfile the full method")
    args = parser.parse_args(argv)
    n_readings = 320 if args.smoke else args.readings
    firings = ring_scans(max(2, n_readings // 16))
    grid = room_grid(0.05)
    total = sum(len(s) for s in firings)
    figures: dict[str, float] = {"readings": total}
    print(f"{total} readings ({len(firings)} ring firings), grid {grid.width}x{grid.height} "
          "at 0.05 m, 5 m sonars")
    if not args.smoke:
        c = compile_seconds()
        figures.update(c)
        print(f"kernels: compile {c['warm cold s']:.1f} s on a machine's first run, load "
              f"{c['warm cached s']:.2f} s per process after (imports {c['import cached s']:.2f} s); "
              f"CPU of the whole process {c['process cpu cold s']:.1f} s cold, "
              f"{c['process cpu cached s']:.1f} s cached")
    warm()  # timed runs below load compiled kernels, as every run but a machine's first
    octo = run_octomap(firings, 0.05)
    if octo is not None:
        figures["octomap"] = total / octo
        figures["octomap cpu"] = total / LAST_CPU[0]
        print(f"{'octomap':<34} {total / octo:10.0f} readings/s "
              f"({figures['octomap cpu']:.0f} per CPU s)")
    variances: dict[str, tuple[int, tuple[float, float]]] = {}
    headline = ""
    for per_scan in args.readings_per_scan:
        scans = group_scans(firings, max(1, per_scan // 16))
        print(f"-- {per_scan} readings per scan ({len(scans)} scans)")
        for name, cfg in METHODS:
            runs = []
            for _ in range(max(1, args.repeat)):
                seconds, mapper = run_mapper(cfg, grid, scans)
                runs.append((seconds, LAST_CPU[0], mapper))
            seconds, _cpu, mapper = min(runs, key=lambda r: r[0])
            rate = total / seconds
            figures[f"{name} {per_scan}/scan"] = rate
            figures[f"{name} {per_scan}/scan cpu"] = total / min(r[1] for r in runs)
            ratio = f"  {octo * rate / total:6.2f}x octomap" if octo else ""
            if octo:
                ratio += (f" ({figures[f'{name} {per_scan}/scan cpu'] / figures['octomap cpu']:.2f}x"
                          " per CPU s)")
            print(f"{name:<34} {rate:10.0f} readings/s{ratio}")
            if per_scan == args.readings_per_scan[0] and cfg.method == "andersone":
                variances[name] = (len(mapper.feature_table()), mapper.feature_variance())
                if name == "andersone+correction":
                    headline = (f"headline (full method, {per_scan}/scan): {rate:.0f} "
                                f"readings/s{ratio}")
    print(headline)
    print(f"\nmean feature variance (ALGORITHM.md §7), {args.readings_per_scan[0]} readings/scan")
    print(f"{'method':<34} {'features':>8} {'trace/2 m2':>11} {'lambda_max m2':>14}")
    for name, (count, (half_trace, lam)) in variances.items():
        print(f"{name:<34} {count:8d} {half_trace:11.5f} {lam:14.5f}")

    if args.profile:
        scans = group_scans(firings, max(1, args.readings_per_scan[0] // 16))
        prof = cProfile.Profile()
        prof.enable()
        run_mapper(MapperConfig(), grid, scans)  # the default method
        prof.disable()
        pstats.Stats(prof).sort_stats("tottime").print_stats(15)
    return figures


if __name__ == "__main__":
    main()
