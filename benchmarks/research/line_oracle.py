"""How far the default method (§11) is from what a perfect wall-line model would give it
(docs/research/forward_walls.md §3).

Usage: ``python -m benchmarks.research.line_oracle LOG TRUTH.yaml OUT [--presence-only]``

Maps LOG with the default method, except that in its surface-aware count pass (pass 3;
the final attribution, pass 4, stops rays with the method's own normals) every cell's
orientation is replaced by the truth's: a cell within ``NEAR_CELLS`` of a true
wall takes that wall's normal (:func:`pipeline.tools.sonar.grid_scene.wall_normals`, a
local line fit of the true wall cells) with consistency 1, so a pass there is discounted by
the measured detection curve at its incidence against the true line; every other cell gets
consistency 0 and ``v̄ = 1``, so a pass there counts in full (no surface to be silent).
With ``--presence-only`` the near cells keep the method's own normal and consistency (the
arcs' bearings): only *where* walls are is known. Prints F1, precision and recall as
``sonarmap evaluate`` scores them (trajectory ``<stem>.truth.csv`` beside the truth, the
log's sensor reach, 0.10 m). An oracle, not a method: it reads the truth.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

NEAR_CELLS = 2.0  # a cell this close (cells) to a true wall is on it (the scorer's 0.10 m)


def oracle_orientation(mapper: object, truth_yaml: Path, presence_only: bool) -> None:
    """Overwrite the forward mapper's normals, consistency and ``v̄`` from the truth."""
    from scipy.ndimage import distance_transform_edt

    from formats.writers.nav2_map import load_nav2_map
    from pipeline.tools.evaluate import OCCUPIED, resample_classes
    from pipeline.tools.sonar.grid_scene import wall_normals

    m = mapper
    truth = load_nav2_map(truth_yaml)
    walls = resample_classes(truth.classes, truth.grid, m.grid)[0] == OCCUPIED  # type: ignore[attr-defined]
    nx, ny, _ = wall_normals(walls, m.grid.resolution)  # type: ignore[attr-defined]
    dist, (ir, ic) = distance_transform_edt(~walls, return_indices=True)
    near = dist <= NEAR_CELLS
    if not presence_only:
        m.nx = np.where(near, nx[ir, ic], m.nx).astype(np.float32)  # type: ignore[attr-defined]
        m.ny = np.where(near, ny[ir, ic], m.ny).astype(np.float32)  # type: ignore[attr-defined]
    q = 1.0 if not presence_only else m.consistency  # type: ignore[attr-defined]
    m.consistency = np.where(near, q, 0.0).astype(np.float32)  # type: ignore[attr-defined]
    m.v_unknown = 1.0  # type: ignore[attr-defined]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("truth", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--presence-only", action="store_true")
    args = ap.parse_args()

    from benchmarks.compare_methods import load_config_for, log_reach
    from pipeline.mapper.forward import ForwardMapper
    from pipeline.methods import Method
    from pipeline.run import run
    from pipeline.tools.evaluate import evaluate_run

    begin = ForwardMapper.begin_pass

    kept: dict[str, object] = {}

    def begin_pass(self: ForwardMapper, index: int) -> None:
        begin(self, index)
        if index == 3:  # the detection curve is measured; the counts start
            kept.update(nx=self.nx, ny=self.ny, consistency=self.consistency,
                        v_unknown=self.v_unknown)
            oracle_orientation(self, args.truth, args.presence_only)
        elif index == 4:  # the final attribution stops rays at the method's own normals
            for k, v in kept.items():
                setattr(self, k, v)

    ForwardMapper.begin_pass = begin_pass  # type: ignore[method-assign]
    cfg = load_config_for(args.log, None)
    cfg = cfg.replace(mapper=dataclasses.replace(cfg.mapper, method=Method.FORWARD))
    run(args.log, args.out, cfg, force=True)
    stem = args.truth.name.split(".")[0]
    traj = args.truth.with_name(f"{stem}.truth.csv")
    ev = evaluate_run(args.out, args.truth, trajectory=traj if traj.is_file() else None,
                      tolerance_m=0.10, sensor_reach_m=log_reach(args.log, cfg))
    print(f"{args.log.name}: F1 {ev.f1:.3f} (precision {ev.precision:.3f}, "
          f"recall {ev.recall:.3f})")


if __name__ == "__main__":
    main()
