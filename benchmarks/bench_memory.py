"""Peak memory of a run versus log length: the same corridor route driven back and forth
for 1x and 10x the time (2 and 20 minutes; ``--smoke``: 30 s and 300 s), each log mapped
in a fresh process; prints peak RSS (VmHWM at exit) of both and their ratio.

Target: ratio <= 1.2 (memory bounded by the mapped area, not by the log's length).

    .venv/bin/python -m benchmarks.bench_memory [--smoke] [--minutes 2] [--factor 10]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
WORLD = ROOT / "sample_logs" / "worlds" / "corridor.toml"
WAYPOINTS = ROOT / "sample_logs" / "worlds" / "corridor.waypoints.csv"
TARGET_RATIO = 1.2

# Run in the child: map the log, print what it measured as one JSON line.
_CHILD = """
import json, sys, time
from pathlib import Path
from pipeline.config import Config
from pipeline.run import run
t0 = time.perf_counter()
r = run(Path(sys.argv[1]), Path(sys.argv[2]), Config())
hwm = next(int(ln.split()[1]) for ln in open('/proc/self/status') if ln.startswith('VmHWM:'))
print(json.dumps({"peak_rss_kib": hwm, "seconds": time.perf_counter() - t0,
                  "readings": r.metrics.counts["readings"], "features": r.metrics.counts["features"]}))
"""


def make_log(path: Path, seconds: float, speed: float = 0.5) -> float:
    """Simulate the corridor route driven back and forth for about ``seconds``; write an
    MCAP (zstd) to ``path``; return the log's duration (s)."""
    from formats.log_writers import write_log
    from pipeline.tools.simulate.simulate import SimOptions, simulate
    from pipeline.tools.simulate.trajectory import load_waypoints
    from pipeline.tools.simulate.world import load_world

    route = load_waypoints(WAYPOINTS)[:2]  # the corridor's two ends
    leg = float(np.hypot(*(route[1] - route[0]))) / speed  # s from one end to the other
    legs = max(1, round(seconds / leg))
    wp = route[np.arange(legs + 1) % 2]  # back and forth over the same ground
    sim = simulate(load_world(WORLD), wp, SimOptions(seed=1, speed=speed, ring_rate_hz=5,
                                                          sonar_model="ideal"))
    content = sim.to_content()
    write_log(content, path, "mcap", compression="zstd")
    t = content.ranges.t_ns
    return float(t.max() - t.min()) / 1e9


def map_in_child(log: Path, out: Path) -> dict[str, float]:
    """Map ``log`` in a fresh interpreter; its peak RSS (KiB), seconds, readings, features."""
    res = subprocess.run(
        [sys.executable, "-c", _CHILD, str(log), str(out)],
        cwd=ROOT, capture_output=True, text=True, check=False,
    )
    if res.returncode != 0:
        raise RuntimeError(f"mapping {log} failed: {res.stderr.strip()}")
    return dict(json.loads(res.stdout.strip().splitlines()[-1]))


def measure(minutes: float, factor: int, work: Path) -> dict[str, dict[str, float]]:
    """Both runs: ``{'1x': {...}, 'Nx': {...}}`` with duration_s added."""
    out: dict[str, dict[str, float]] = {}
    for label, mult in (("1x", 1), (f"{factor}x", factor)):
        log = work / f"corridor_{label}.mcap"
        duration = make_log(log, minutes * 60 * mult)
        row = map_in_child(log, work / f"out_{label}")
        row["duration_s"] = duration
        row["log_mib"] = log.stat().st_size / 2**20
        out[label] = row
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--smoke", action="store_true", help="30 s and 300 s logs")
    ap.add_argument("--minutes", type=float, default=2.0, help="length of the 1x log")
    ap.add_argument("--factor", type=int, default=10)
    args = ap.parse_args(argv)
    minutes = 0.5 if args.smoke else args.minutes
    with tempfile.TemporaryDirectory(prefix="sonarmap-bench-mem-") as tmp:
        rows = measure(minutes, args.factor, Path(tmp))
    print(f"{'log':<5} {'duration s':>10} {'log MiB':>8} {'readings':>9} {'features':>9} "
          f"{'map s':>7} {'peak RSS MiB':>13}")
    for label, r in rows.items():
        print(f"{label:<5} {r['duration_s']:>10.0f} {r['log_mib']:>8.1f} {r['readings']:>9.0f} "
              f"{r['features']:>9.0f} {r['seconds']:>7.1f} {r['peak_rss_kib'] / 1024:>13.1f}")
    a, b = rows.values()
    ratio = b["peak_rss_kib"] / a["peak_rss_kib"]
    verdict = "ok" if ratio <= TARGET_RATIO else "ABOVE TARGET"
    print(f"peak RSS ratio {args.factor}x/1x = {ratio:.3f} (target <= {TARGET_RATIO}: {verdict})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
