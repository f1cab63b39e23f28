"""End to end: ``sonarmap run`` on a simulated long log of a 16-sonar ring, and its scaling.

Usage: ``python benchmarks/bench_end_to_end.py [--seconds 3600] [--fractions 0.25 0.5 1]
[--rss-factor 10] [--repeat 3] [--smoke] [--profile FILE]``

Input (deterministic, no downloads): the simulator (:mod:`pipeline.tools.simulate`) drives the
Pioneer ring (16 sonars, 30° beams, 0.1-5 m, ring at 10 Hz → 160 readings/s) through the
office world's waypoint tour and back again, in a loop, for ``--seconds`` (default one hour
= 576k readings, poses at 20 Hz), written as MCAP (ROS 2 CDR, zstd chunks). Logs are cached
under ``<tmp>/sonarmap-bench/`` keyed by their parameters, so reruns do not regenerate them.

Each log is mapped by ``sonarmap run`` in a fresh process (the real command: imports, both
passes, mapping, outputs), ``--repeat`` times; the table gives the median wall seconds,
readings/s, the share of each stage (``metrics.json`` timing; "outputs+startup" = wall −
the stages) and the peak RSS. Scaling: 1/4, 1/2, 1× of the log (wall time should grow
linearly) and the peak RSS of a ``--rss-factor``× longer log (target ≤ 1.2× of 1×). The 1×
log is mapped once more with ``--refine-poses`` (target < 30 s; issue 63).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
WORLDS = REPO / "sample_logs" / "worlds"
CACHE_VERSION = 1  # bump when the log generation below changes
RING_HZ = 10.0
STAGES = ("ingest", "pose_sync", "scan_building", "mapping")


@dataclass(frozen=True)
class LogSpec:
    """Parameters of one simulated benchmark log (they are its cache key)."""

    seconds: float = 3600.0
    world: str = "office"
    seed: int = 1
    compression: str = "zstd"

    @property
    def key(self) -> str:
        return (
            f"v{CACHE_VERSION}-{self.world}-{self.seconds:g}s-seed{self.seed}-"
            f"ring{RING_HZ:g}hz-{self.compression}"
        )


def cache_dir() -> Path:
    """``<system temp>/sonarmap-bench`` (override with ``SONARMAP_BENCH_CACHE``)."""
    env = os.environ.get("SONARMAP_BENCH_CACHE")
    return Path(env) if env else Path(tempfile.gettempdir()) / "sonarmap-bench"


def simulate_log(spec: LogSpec, path: Path) -> int:
    """Simulate ``spec`` and write it as MCAP to ``path``; returns the number of readings."""
    from formats.log_writers import write_log
    from pipeline.tools.simulate import SimOptions, load_waypoints, load_world, simulate
    from pipeline.tools.simulate.simulate import SimRanges
    from pipeline.tools.simulate.trajectory import Trajectory

    world = load_world(WORLDS / f"{spec.world}.toml")
    wp = load_waypoints(WORLDS / f"{spec.world}.waypoints.csv")
    # The tour and back again is a closed loop through doors only; drive it until the
    # log is long enough, then cut it at exactly ``seconds``.
    loop = np.vstack([wp, wp[-2::-1]])
    one = simulate(world, loop, SimOptions(seed=spec.seed, ring_rate_hz=RING_HZ, sonar_model="ideal"))
    loop_s = (one.poses.t_ns[-1] - one.poses.t_ns[0]) / 1e9
    laps = int(spec.seconds // loop_s) + 1
    tour = np.vstack([loop[:-1]] * laps + [loop[-1:]])
    opt = SimOptions(seed=spec.seed, ring_rate_hz=RING_HZ, sonar_model="ideal")
    sim = simulate(world, tour, opt)
    end = opt.start_ns + round(spec.seconds * 1e9)
    r = sim.ranges
    keep = r.t_ns < end
    ranges = SimRanges(*(getattr(r, f.name)[keep] for f in dataclasses.fields(SimRanges)))
    p = sim.poses
    # Keep the first pose at or after the end, so the last readings still have a pose.
    n_pose = int(np.searchsorted(p.t_ns, end, side="left")) + 1
    poses = Trajectory(p.t_ns[:n_pose], p.x[:n_pose], p.y[:n_pose], p.yaw[:n_pose])
    sim = dataclasses.replace(sim, ranges=ranges, poses=poses, true_poses=poses)
    write_log(sim.to_content(), path, "mcap", compression=spec.compression)
    return len(ranges)


def cached_log(spec: LogSpec, verbose: bool = True) -> Path:
    """The log for ``spec``, generated on first use into the cache (atomically)."""
    d = cache_dir() / spec.key
    log = d / "log.mcap"
    if log.exists():
        return log
    d.mkdir(parents=True, exist_ok=True)
    tmp = d / f"log.{os.getpid()}.tmp.mcap"
    tmp.unlink(missing_ok=True)
    t0 = time.perf_counter()
    n = simulate_log(spec, tmp)
    tmp.replace(log)
    if verbose:
        print(
            f"# generated {log} ({n} readings, {log.stat().st_size / 1e6:.1f} MB) "
            f"in {time.perf_counter() - t0:.1f} s",
            flush=True,
        )
    return log


@dataclass
class RunFigures:
    """One ``sonarmap run``: wall seconds, stage seconds, readings and peak RSS (MiB)."""

    wall: float
    stages: dict[str, float]
    readings: int
    rss_mb: float
    cpu: float = 0.0  # the child's user + system seconds (other jobs inflate wall, not this)


# The child runs the real CLI entry point, then reports its own peak RSS (VmHWM). Not
# metrics.json's ru_maxrss: that also counts the parent's pages between fork and exec,
# so a big benchmark process would inflate it.
_CHILD = """
import sys
from cli.app import main
sys.argv = ["sonarmap", *sys.argv[1:]]
try:
    main()
finally:
    with open("/proc/self/status", encoding="ascii") as f:
        hwm = next(line for line in f if line.startswith("VmHWM:"))
    print("VmHWM_KB", hwm.split()[1], file=sys.stderr)
"""


def run_once(log: Path, out: Path, extra: tuple[str, ...] = ()) -> RunFigures:
    """``sonarmap run log -o out --force --quiet`` in a fresh process, timed."""
    cmd = [sys.executable, "-c", _CHILD, "run", str(log), "-o", str(out), "--force", "--quiet",
           *extra]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    timing = metrics["timing"]
    hwm = [ln.split()[1] for ln in proc.stderr.splitlines() if ln.startswith("VmHWM_KB")]
    rss = int(hwm[-1]) / 1024.0 if hwm else float(timing["peak_rss_mb"])
    return RunFigures(
        wall=wall,
        stages={k: float(timing["stage_seconds"].get(k, 0.0)) for k in STAGES},
        readings=int(metrics["counts"]["readings"]),
        rss_mb=rss,
        cpu=cpu,
    )


def profile_run(log: Path, report: Path) -> None:
    """One ``sonarmap run`` of ``log`` under pyinstrument; its call tree goes to ``report``."""
    with tempfile.TemporaryDirectory(prefix="bench_profile_") as tmp:
        cmd = [sys.executable, "-m", "pyinstrument", "--outfile", str(report), "-m", "cli",
               "run", str(log), "-o", str(Path(tmp) / "out"), "--quiet"]
        subprocess.run(cmd, check=True)
    print(f"# pyinstrument call tree of `sonarmap run {log}` written to {report}")


def median_run(log: Path, out: Path, repeat: int) -> RunFigures:
    """The run with the median wall time of ``repeat`` runs (the machine is shared)."""
    runs = sorted((run_once(log, out) for _ in range(repeat)), key=lambda r: r.wall)
    return runs[(len(runs) - 1) // 2]


def stage_shares(r: RunFigures) -> dict[str, float]:
    """Share of the wall time per stage, plus "outputs+startup" (the rest)."""
    shares = {k: v / r.wall for k, v in r.stages.items()}
    shares["outputs+startup"] = max(0.0, 1.0 - sum(shares.values()))
    return shares


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Run the benchmark, print the tables; returns the headline figures."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3600.0, help="length of the 1x log, s")
    ap.add_argument("--fractions", type=float, nargs="+", default=[0.25, 0.5, 1.0])
    ap.add_argument("--rss-factor", type=float, default=10.0,
                    help="peak RSS is compared between 1x and this many times longer (0: skip)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per log (median reported)")
    ap.add_argument("--smoke", action="store_true", help="tiny logs, one run each")
    ap.add_argument("--profile", metavar="FILE", type=Path,
                    help="only profile one run of the 1x log with pyinstrument (call tree "
                         "as text into FILE; pyinstrument comes with the dev extra)")
    args = ap.parse_args(argv)
    if args.profile is not None:
        profile_run(cached_log(LogSpec(seconds=args.seconds)), args.profile)
        return {}
    if args.smoke:
        args.seconds, args.fractions, args.rss_factor, args.repeat = 20.0, [0.5, 1.0], 2.0, 1
    base = LogSpec(seconds=args.seconds)
    figures: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="bench_e2e_") as tmp:
        rows: list[tuple[float, RunFigures]] = []
        for frac in sorted(set(args.fractions)):
            log = cached_log(dataclasses.replace(base, seconds=args.seconds * frac))
            rows.append((frac, median_run(log, Path(tmp) / f"out_{frac:g}", args.repeat)))
        print(f"\nsonarmap run, {base.world} world, 16-sonar ring at {RING_HZ:g} Hz, MCAP "
              f"{base.compression}; median of {args.repeat} run(s)")
        head = (f"{'log':>8} {'readings':>9} {'wall s':>7} {'CPU s':>6} {'readings/s':>10} "
                f"{'RSS MB':>7}  ")
        print(head + "  ".join(f"{k:>8}" for k in (*STAGES, "out+start")))
        for frac, r in rows:
            sh = stage_shares(r)
            print(
                f"{frac:>7g}x {r.readings:>9} {r.wall:>7.2f} {r.cpu:>6.2f} "
                f"{r.readings / r.wall:>10.0f} "
                f"{r.rss_mb:>7.0f}  " + "  ".join(f"{100 * v:>7.1f}%" for v in sh.values())
            )
            figures[f"wall {frac:g}x s"] = r.wall
            figures[f"cpu {frac:g}x s"] = r.cpu
            figures[f"readings {frac:g}x"] = r.readings
            figures[f"rss {frac:g}x MB"] = r.rss_mb
            for k, v in sh.items():
                figures[f"share {k} {frac:g}x"] = v
        one = dict(rows).get(1.0)
        if one is not None:
            print(f"1x: {one.wall:.2f} s wall, {one.cpu:.2f} s CPU (target < 8 s), "
                  f"{one.readings / one.wall:.0f} readings/s; load average "
                  f"{os.getloadavg()[0]:.1f}")
            lo_frac, lo = rows[0]
            if lo_frac < 1.0:
                growth = (one.wall / lo.wall) / (1.0 / lo_frac)
                figures["linearity"] = growth
                print(f"wall time growth {lo_frac:g}x -> 1x: {one.wall / lo.wall:.2f}x for "
                      f"{1 / lo_frac:g}x the log (ratio to linear {growth:.2f})")
            log_1x = cached_log(dataclasses.replace(base, seconds=args.seconds), verbose=False)
            refined = run_once(log_1x, Path(tmp) / "out_refined", ("--refine-poses",))
            figures["refined wall 1x s"] = refined.wall
            figures["refined cpu 1x s"] = refined.cpu
            print(f"1x with --refine-poses: {refined.wall:.2f} s wall, {refined.cpu:.2f} s CPU "
                  f"(target < 30 s; {refined.cpu / one.cpu:.2f}x the unrefined CPU)")
            if args.rss_factor > 1:
                long_spec = dataclasses.replace(base, seconds=args.seconds * args.rss_factor)
                long_log = cached_log(long_spec)
                big = run_once(long_log, Path(tmp) / "out_long")
                figures[f"wall {args.rss_factor:g}x s"] = big.wall
                figures[f"cpu {args.rss_factor:g}x s"] = big.cpu
                figures[f"rss {args.rss_factor:g}x MB"] = big.rss_mb
                figures["rss growth"] = big.rss_mb / one.rss_mb
                print(f"peak RSS 1x {one.rss_mb:.0f} MB -> {args.rss_factor:g}x "
                      f"{big.rss_mb:.0f} MB: {big.rss_mb / one.rss_mb:.2f}x (target <= 1.2x); "
                      f"{args.rss_factor:g}x wall {big.wall:.1f} s")
    return figures


if __name__ == "__main__":
    main()
