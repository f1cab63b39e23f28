"""A suite against a batch: ``sonarmap regress --suite`` of the repository's sample logs on
2 workers, beside ``sonarmap batch`` of the same logs on 2 workers (target ≤ 1.2×).

Usage: ``python -m benchmarks.bench_regress_suite [--repeat N] [--smoke]``

The logs: the sample logs that map with the default configuration (office, corridor,
orchard, the Intel lab, slow odometry; ``--smoke``: slow odometry only), their truths in
the suite so that the suite scores F1 as CI would. The goldens are made first with
``--update`` (not timed). Each timed figure is a whole command in a fresh process — the
cluster's start, every log mapped, the comparison, the exit — the two commands
alternating, the fastest of ``--repeat`` kept; the batch maps into a fresh directory
each time (``--rerun``: no log skipped).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_logs"
LOGS = (  # name, log, truth, true trajectory (relative to sample_logs/)
    ("office", "office/office.mcap", "office/office.truth.yaml", "office/office.truth.csv"),
    ("corridor", "corridor/corridor.mcap", "corridor/corridor.truth.yaml",
     "corridor/corridor.truth.csv"),
    ("orchard", "orchard/orchard.mcap", "orchard/orchard.truth.yaml",
     "orchard/orchard.truth.csv"),
    ("intel-lab", "intel-lab/intel.mcap", "intel-lab/intel.laser.yaml",
     "intel-lab/intel.truth.csv"),
    ("slow-odometry", "slow-odometry", None, None),
)


def suite_text(logs: tuple[tuple[str, str, str | None, str | None], ...]) -> str:
    parts = []
    for name, log, truth, traj in logs:
        parts.append(f'[[log]]\nname = "{name}"\npath = "{SAMPLES / log}"\n')
        if truth is not None:
            parts.append(f'truth = "{SAMPLES / truth}"\ntruth_trajectory = "{SAMPLES / traj}"\n')
    return "\n".join(parts)


def _timed(args: list[str], cwd: Path) -> tuple[float, float]:
    """Wall and CPU seconds of one command (CPU: the process and the workers it waited for,
    which the machine's other jobs barely change)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "cli", *args], cwd=cwd, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Run, print; returns the logs, both walls (s) and their ratio."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--smoke", action="store_true", help="one small log, once")
    args = ap.parse_args(argv)
    logs = LOGS[-1:] if args.smoke else LOGS
    repeat = 1 if args.smoke else args.repeat
    work = Path(tempfile.mkdtemp(prefix="bench_regress_suite_"))
    try:
        (work / "suite.toml").write_text(suite_text(logs), encoding="utf-8")
        suite = ["regress", "--suite", "suite.toml", "--goldens", "goldens", "--workers", "2",
                 "-q"]
        _timed([*suite, "--update"], work)
        batch = ["batch", *(str(SAMPLES / log) for _, log, _, _ in logs), "-o", "out",
                 "--workers", "2", "--rerun", "-q"]
        runs: dict[str, list[tuple[float, float]]] = {"suite": [], "batch": []}
        for _ in range(repeat):
            shutil.rmtree(work / "out", ignore_errors=True)
            runs["batch"].append(_timed(batch, work))
            runs["suite"].append(_timed(suite, work))
        s, b = min(runs["suite"]), min(runs["batch"])  # the fastest wall, with its CPU
        print(f"{len(logs)} sample logs on 2 workers: regress --suite {s[0]:.2f} s "
              f"({s[1]:.1f} s CPU), batch {b[0]:.2f} s ({b[1]:.1f} s CPU), ratio "
              f"{s[0] / b[0]:.2f}x wall, {s[1] / b[1]:.2f}x CPU (target <= 1.2x); all walls: "
              f"suite {', '.join(f'{w:.2f}' for w, _ in runs['suite'])}, batch "
              f"{', '.join(f'{w:.2f}' for w, _ in runs['batch'])}")
        return {"logs": len(logs), "suite": s[0], "batch": b[0], "ratio": s[0] / b[0],
                "suite cpu": s[1], "batch cpu": b[1], "cpu ratio": s[1] / b[1]}
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
