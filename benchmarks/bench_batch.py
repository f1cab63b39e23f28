"""Batch scaling: wall time of ``run_batch`` over 8 logs with 1 and with 2 local workers.

Usage: ``python benchmarks/bench_batch.py [--logs N] [--steps S] [--smoke] [--keep DIR]``

Input (deterministic): N single-layout CSV logs of a robot driving ``S`` pose steps (0.1 s,
5 cm apart) up and down a 2.4 m wide corridor with pillars; an 8-sonar ring (30° beams,
0.1-5 m) fires once per step; ranges are the nearest wall or pillar along the beam axis
plus 1 cm noise (seeded per log). Each batch gets a fresh LocalCluster (as ``sonarmap batch
--workers N`` starts one, its workers warmed as they start: pipeline/tools/batch_warm.py), timed
apart from the batch; both map into fresh directories.
Prints seconds per batch, per log and the speed-up with and without the start-up (target
≥ 1.8× on 2 cores).
"""

from __future__ import annotations

import argparse
import math
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from pipeline.tools.batch import WORKER_PRELOAD, run_batch

YAWS_DEG = (-90.0, -50.0, -30.0, -10.0, 10.0, 30.0, 50.0, 90.0)
HALF_WIDTH = 1.2  # m, corridor walls at y = ±1.2
LENGTH = 15.0  # m
PILLARS = ((3.0, 0.9, 0.25), (6.0, -0.9, 0.25), (9.5, 0.9, 0.3), (12.0, -0.9, 0.25))  # x, y, r


def config_text() -> str:
    mounts = "\n".join(
        f'[[sensors.mounts]]\nname = "s{i}"\nx = 0.1\nyaw_deg = {yaw}\nfov_deg = 30.0\n'
        f"min_range = 0.1\nmax_range = 5.0\n"
        for i, yaw in enumerate(YAWS_DEG)
    )
    return "[grid]\nresolution = 0.05\n\n" + mounts


def _ray_ranges(ox: np.ndarray, oy: np.ndarray, th: np.ndarray) -> np.ndarray:
    """Distance (m) along each ray to the first wall or pillar; +inf beyond 5 m."""
    c, s = np.cos(th), np.sin(th)
    d = np.full(ox.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for wall_y in (HALF_WIDTH, -HALF_WIDTH):
            t = (wall_y - oy) / s
            d = np.where((t > 0) & (t < d), t, d)
        for wall_x in (0.0, LENGTH):
            t = (wall_x - ox) / c
            d = np.where((t > 0) & (t < d), t, d)
    for px, py, r in PILLARS:
        bx, by = px - ox, py - oy
        proj = bx * c + by * s
        disc = r * r - (bx * bx + by * by - proj * proj)
        t = proj - np.sqrt(np.maximum(disc, 0.0))
        d = np.where((disc > 0) & (t > 0) & (t < d), t, d)
    return np.where(d > 5.0, np.inf, d)


def write_log(path: Path, steps: int, seed: int) -> None:
    """One corridor log (8 readings per step) as CSV, deterministic for a seed."""
    rng = np.random.default_rng(seed)
    k = np.arange(steps)
    span = LENGTH - 2.0
    travel = (k * 0.05 + seed * 0.7) % (2 * span)
    x = 1.0 + np.where(travel < span, travel, 2 * span - travel)
    yaw = np.where(travel < span, 0.0, math.pi)
    y = 0.15 * np.sin(k * 0.02 + seed)
    n = len(YAWS_DEG)
    t = np.repeat(k * 0.1, n) + np.tile(np.arange(n) * 0.01, steps)
    sensor = np.tile(np.arange(n), steps)
    rx, ry, ryaw = np.repeat(x, n), np.repeat(y, n), np.repeat(yaw, n)
    ox, oy = rx + 0.1 * np.cos(ryaw), ry + 0.1 * np.sin(ryaw)
    beam = ryaw + np.radians(np.asarray(YAWS_DEG))[sensor]
    r = _ray_ranges(ox, oy, beam) + rng.normal(0.0, 0.01, t.shape)
    lines = ["t,x,y,yaw,sensor,range"]
    lines += [
        f"{ti:.3f},{xi:.4f},{yi:.4f},{wi:.5f},s{si},{'inf' if not np.isfinite(ri) else f'{ri:.4f}'}"
        for ti, xi, yi, wi, si, ri in zip(t, rx, ry, ryaw, sensor, r, strict=True)
    ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def batch_seconds(logs: Path, out: Path, cfg: Path, workers: int) -> tuple[float, float, list[float]]:
    """(cluster start-up s, batch wall s, per-log s) on a fresh local cluster of ``workers``."""
    from distributed import LocalCluster

    t0 = time.perf_counter()
    # As sonarmap batch's local cluster: workers warmed as it starts (pipeline.tools.batch_warm).
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      host="127.0.0.1", dashboard_address=None, silence_logs=40,
                      memory_limit=0, preload=[WORKER_PRELOAD]) as cluster:
        startup = time.perf_counter() - t0
        t1 = time.perf_counter()
        result = run_batch([logs], out, cfg, scheduler=cluster.scheduler_address)
        wall = time.perf_counter() - t1
    if not result.ok:
        raise SystemExit(f"batch failed: {[o.error for o in result.failures]}")
    return startup, wall, [o.seconds for o in result.outcomes]


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Run the benchmark, print it; returns logs, readings per log, walls and the speed-up."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=8)
    ap.add_argument("--steps", type=int, default=3000, help="pose steps per log (8 readings each)")
    ap.add_argument("--smoke", action="store_true", help="tiny run: 2 logs of 200 steps")
    ap.add_argument("--keep", type=Path, help="work in this directory and keep it")
    args = ap.parse_args(argv)
    n_logs, steps = (2, 200) if args.smoke else (args.logs, args.steps)

    work = args.keep or Path(tempfile.mkdtemp(prefix="bench_batch_"))
    try:
        logs = work / "logs"
        logs.mkdir(parents=True, exist_ok=True)
        cfg = work / "sonarmap.toml"
        cfg.write_text(config_text(), encoding="utf-8")
        for i in range(n_logs):
            write_log(logs / f"corridor{i:02d}.csv", steps, seed=i)
        print(f"{n_logs} logs x {steps * len(YAWS_DEG)} readings")
        times = {}
        for workers in (1, 2):
            out = work / f"out_w{workers}"
            shutil.rmtree(out, ignore_errors=True)
            startup, wall, per_log = batch_seconds(logs, out, cfg, workers)
            times[workers] = (startup + wall, wall)
            print(f"workers={workers}: {wall:7.2f} s batch wall (+{startup:.2f} s cluster "
                  f"start-up); per log {min(per_log):.2f}-{max(per_log):.2f} s "
                  f"(mean {sum(per_log) / len(per_log):.2f} s)")
        print(f"speed-up 2 vs 1 workers: {times[1][1] / times[2][1]:.2f}x batch wall, "
              f"{times[1][0] / times[2][0]:.2f}x including cluster start-up")
        return {"logs": n_logs, "readings": steps * len(YAWS_DEG), "wall 1": times[1][1],
                "wall 2": times[2][1], "speedup": times[1][1] / times[2][1]}
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
