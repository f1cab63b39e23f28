"""How thick the buildings' reference walls are under each wall rule (docs/EVALUATION.md).

Usage: ``python -m benchmarks.reference_walls``

For the Intel lab and the four Radish buildings, the laser reference map's wall cells
within 3 m of the laser's path under: one hit enough (the log-odds alone), two hits, and
two hits on more than a share of the beams reaching the cell, for the reference's share
(0.25) and a majority (0.5). For each share: its wall cells against the two-hit rule's,
its cells more than 0.10 m from any two-hit wall (new walls), and the two-hit wall cells
more than 0.10 m from any of its walls (walls it loses).
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


SHARES = (0.25, 0.5)


def wall_counts(path: Path) -> tuple[int, int, list[tuple[int, int, int]]]:
    """(one-hit, two-hit, per share (walls, new walls, lost two-hit walls)) within reach."""
    log = load_laser_log(path, Config())
    m = laser_occupancy_map(log, LaserMapOptions(min_hits=0, min_hit_share=0.0))
    g, h, passes = m.grid, m.hits, m.passes
    lx, ly, _ = log.laser_poses()
    on_path = np.zeros(g.shape, bool)
    on_path[np.floor((ly - g.origin_y) / g.resolution).astype(int),
            np.floor((lx - g.origin_x) / g.resolution).astype(int)] = True
    near = distance_transform_edt(~on_path) * g.resolution <= REACH_M
    one = m.probability > 0.65
    two = one & (h >= 2)
    far_from_two = distance_transform_edt(~two) * g.resolution > 0.10
    per_share = []
    for share in SHARES:
        rule = two & (h > share * (h + passes))
        lost = two & near & (distance_transform_edt(~rule) * g.resolution > 0.10)
        per_share.append((int((rule & near).sum()), int((rule & near & far_from_two).sum()),
                          int(lost.sum())))
    return int((one & near).sum()), int((two & near).sum()), per_share


def main() -> int:
    head = ["building", "one hit", "two hits"]
    for share in SHARES:
        head += [f"> {share:.0%} of beams: walls (/ two hits)", "new", "two-hit walls lost"]
    print("| " + " | ".join(head) + " |")
    print("|---" + "|--:" * (len(head) - 1) + "|")
    for name, path in BUILDINGS.items():
        one, two, per_share = wall_counts(path)
        cells = [name, f"{one:,}", f"{two:,}"]
        for walls, new, lost in per_share:
            cells += [f"{walls:,} ({walls / two:.2f})", str(new), f"{lost} ({lost / two:.1%})"]
        print("| " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
