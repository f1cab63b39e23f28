"""The pose refinement's time target (issue 63: a refined run takes at most 3× the time of
an unrefined one), measured as a user meets it: whole ``sonarmap run`` processes.

Usage::

    python -m benchmarks.refine_time [--cases NAME ...] [--logs LOG ...] [--rounds 5]
        [--work DIR]

Each case is ``make compare``'s drifted log (:func:`benchmarks.compare_methods.drifted_case`:
3 % scale error and 0.8°/m heading bias, or a building's own wheel odometry), plus any
other world of ``sample_logs/worlds`` by name (``loop``: a small floor, where Python's
start-up weighs most), plus any log given by path (``--logs``: e.g. ``make bench``'s hour of
a 16-sonar ring). Every round runs ``python -m cli run LOG -o OUT`` without and with
``--refine-poses``, alternating, so a slow moment of the machine touches both; a case's
figure is the smallest of its rounds (what the code costs, not what the machine did
meanwhile), in wall seconds and in CPU seconds (user + system of the process: what it
costs on a machine shared with other work). Beside the whole processes, the refined run's own stage timings (its
``metrics.json``) say where the time went: the refinement stage against the mapping.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from benchmarks.compare_methods import DRIFT_BIAS_DEG_PER_M, DRIFT_CASES, DRIFT_SCALE, drifted_case
from pipeline.cores import usable_cores
from pipeline.drift import DriftModel

REPO = Path(__file__).resolve().parents[1]
TARGET = 3.0  # refined / unrefined wall time, whole processes
DEFAULT_CASES = ("loop", *DRIFT_CASES)


@dataclass(frozen=True)
class Timed:
    """One case: the smallest wall time of its rounds, unrefined and refined (s), the
    refined run's stage seconds (refinement, mapping) from its metrics.json, and the
    smallest CPU time of the rounds (s)."""

    name: str
    unrefined_s: float
    refined_s: float
    refinement_stage_s: float
    mapping_stage_s: float
    unrefined_cpu_s: float = float("nan")
    refined_cpu_s: float = float("nan")

    @property
    def ratio(self) -> float:
        return self.refined_s / self.unrefined_s


Runner = Callable[[Path, Path, bool], tuple[float, float]]  # (log, out, refine) → wall, CPU s


def run_process(log: Path, out: Path, refine: bool) -> tuple[float, float]:
    """Wall and CPU seconds (user + system) of one ``sonarmap run`` process (``python -m
    cli``, this interpreter)."""
    import resource

    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "cli", "run", str(log), "-o", str(out), "--quiet"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd + (["--refine-poses"] if refine else []), cwd=REPO, check=True,
                   capture_output=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def time_case(name: str, log: Path, work: Path, rounds: int, runner: Runner = run_process
              ) -> Timed:
    """``rounds`` alternating unrefined / refined runs of ``log``; the smallest of each."""
    unrefined, refined = [], []
    for _ in range(rounds):
        unrefined.append(runner(log, work / f"{name}-unrefined", False))
        refined.append(runner(log, work / f"{name}-refined", True))
    stages = json.loads((work / f"{name}-refined" / "metrics.json").read_text())
    seconds = stages["timing"]["stage_seconds"]
    return Timed(name, min(w for w, _ in unrefined), min(w for w, _ in refined),
                 float(seconds.get("pose_refinement", 0.0)), float(seconds.get("mapping", 0.0)),
                 min(c for _, c in unrefined), min(c for _, c in refined))


def markdown(rows: list[Timed]) -> str:
    """The table, and a last line with the largest ratio against the target."""
    lines = ["| case | unrefined (s) | refined (s) | refined / unrefined | refinement stage (s) "
             "| mapping stage (s) | CPU s unrefined | CPU s refined | CPU ratio |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    lines += [f"| {r.name} | {r.unrefined_s:.2f} | {r.refined_s:.2f} | {r.ratio:.2f}× | "
              f"{r.refinement_stage_s:.2f} | {r.mapping_stage_s:.2f} | {r.unrefined_cpu_s:.2f} "
              f"| {r.refined_cpu_s:.2f} | {r.refined_cpu_s / r.unrefined_cpu_s:.2f}× |"
              for r in rows]
    if rows:
        worst = max(rows, key=lambda r: r.ratio)
        met = sum(r.ratio <= TARGET for r in rows)
        lines.append(f"\n{met} / {len(rows)} at most {TARGET:g}× (largest: {worst.name}, "
                     f"{worst.ratio:.2f}×)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="*", default=list(DEFAULT_CASES),
                        help="make compare's drifted cases or worlds of sample_logs/worlds "
                        "(none: --cases alone)")
    parser.add_argument("--logs", nargs="+", type=Path, default=[],
                        help="logs timed as they are (named by their directory and file)")
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds per case")
    parser.add_argument("--work", type=Path, help="keep the logs and runs here")
    args = parser.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="sonarmap-refine-time-"))
    work.mkdir(parents=True, exist_ok=True)
    drift = DriftModel(DRIFT_SCALE, DRIFT_BIAS_DEG_PER_M)
    rows = []
    for name in args.cases:
        log = work / f"{name}_drifted.mcap"
        drifted_case(name, log, drift)
        rows.append(time_case(name, log, work, args.rounds))
        print(f"{name}: {rows[-1].ratio:.2f}×", file=sys.stderr, flush=True)
    for path in args.logs:
        name = f"{path.parent.name}-{path.stem}"
        rows.append(time_case(name, path, work, args.rounds))
        print(f"{name}: {rows[-1].ratio:.2f}×", file=sys.stderr, flush=True)
    print(markdown(rows))
    cores = usable_cores()
    print(f"on {cores} usable core{'s' * (cores != 1)} (the process's CPU affinity; "
          "`taskset -c 0` runs it on one)")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
