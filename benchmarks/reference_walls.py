"""How thick the buildings' reference walls are under each wall rule (docs/EVALUATION.md).

Usage: ``python -m benchmarks.reference_walls``

For the Intel lab and the four Radish buildings, the laser reference map's wall cells
within 3 m of the laser's path under three rules: one hit enough (the log-odds alone),
two hits, and the reference's rule (two hits on more than 25 % of the beams reaching the
cell); the last column counts the rule's wall cells more than 0.10 m from any two-hit wall.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from pipeline.config import Config
from pipeline.tools.emulate.laser_input import load_laser_log
from pipeline.tools.emulate.laser_map import LaserMapOptions, laser_occupancy_map

REPO = Path(__file__).resolve().parents[1]
BUILDINGS = {
    "Intel lab": REPO / "sample_logs/intel-lab/intel-corrected.log.gz",
    **{name: REPO / f"sample_logs/radish/{stem}-corrected.log.gz" for name, stem in (
        ("Freiburg 101", "freiburg-101"), ("Örebro", "orebro"), ("FHW museum", "fhw"),
        ("Belgioioso", "belgioioso"))},
}
REACH_M = 3.0


def wall_counts(path: Path) -> tuple[int, int, int, int]:
    """(one-hit, two-hit, rule, rule cells > 0.10 m from a two-hit wall) within reach."""
    log = load_laser_log(path, Config())
    opt = LaserMapOptions()
    m = laser_occupancy_map(log, LaserMapOptions(min_hits=0, min_hit_share=0.0))
    g, h, passes = m.grid, m.hits, m.passes
    lx, ly, _ = log.laser_poses()
    on_path = np.zeros(g.shape, bool)
    on_path[np.floor((ly - g.origin_y) / g.resolution).astype(int),
            np.floor((lx - g.origin_x) / g.resolution).astype(int)] = True
    near = distance_transform_edt(~on_path) * g.resolution <= REACH_M
    one = m.probability > 0.65
    two = one & (h >= 2)
    rule = two & (h > opt.min_hit_share * (h + passes))
    far = (rule & near & (distance_transform_edt(~two) * g.resolution > 0.10)).sum()
    return int((one & near).sum()), int((two & near).sum()), int((rule & near).sum()), int(far)


def main() -> int:
    print("| building | one hit | two hits | two hits, > 25 % of beams | rule / two hits "
          "| rule cells > 0.10 m from a two-hit wall |")
    print("|---|--:|--:|--:|--:|--:|")
    for name, path in BUILDINGS.items():
        one, two, rule, far = wall_counts(path)
        print(f"| {name} | {one:,} | {two:,} | {rule:,} | {rule / two:.2f} | {far} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
