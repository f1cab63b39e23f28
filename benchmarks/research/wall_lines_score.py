"""One compare row with the default method and ``wall_line_half_length_m`` set
(docs/research/forward_walls.md §5).

Usage: ``python -m benchmarks.research.wall_lines_score LOG TRUTH.yaml OUT HALF_LENGTH_M``
(0 = off, the default before wall lines). Scores as ``sonarmap evaluate`` and ``make compare`` do
(trajectory ``<stem>.truth.csv`` beside the truth, the log's sensor reach, 0.10 m) and
prints F1, precision, recall and the run's seconds.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path


def main() -> None:
    from benchmarks.compare_methods import load_config_for, log_reach
    from pipeline.methods import Method
    from pipeline.run import run
    from pipeline.tools.evaluate import evaluate_run

    log, truth, out = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])
    half = float(sys.argv[4])
    cfg = load_config_for(log, None)
    cfg = cfg.replace(mapper=dataclasses.replace(cfg.mapper, method=Method.FORWARD,
                                                 wall_line_half_length_m=half))
    t0 = time.perf_counter()
    run(log, out, cfg, force=True)
    stem = truth.name.split(".")[0]
    traj = truth.with_name(f"{stem}.truth.csv")
    ev = evaluate_run(out, truth, trajectory=traj if traj.is_file() else None,
                      tolerance_m=0.10, sensor_reach_m=log_reach(log, cfg))
    print(f"{log.name} half length {half} m: F1 {ev.f1:.3f} (P {ev.precision:.3f}, "
          f"R {ev.recall:.3f}) {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
