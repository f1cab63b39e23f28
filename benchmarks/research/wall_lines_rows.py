"""The default method on `make compare`'s 16 rows and the 4 held-out emulations, with
mapper keys overridden (docs/research/forward_walls.md §6).

Usage: ``python -m benchmarks.research.wall_lines_rows OUTDIR [KEY=VALUE ...]
[--variant SPEC] [--only NAME ...]`` (mapper keys; ``--variant``: one of
:mod:`benchmarks.research.wall_lines_variants`).

Logs are read from ``SONARMAP_COMPARE`` (default ``build/compare``; the worlds' ideal logs
and the Intel lab's from ``sample_logs/``) and ``SONARMAP_HELD`` (default
``/tmp/q57/held``: ``sonarmap emulate … --sonar-model realistic --sonar-param
critical_angle_median_deg=12|30 --seed 7``). Each row is scored as ``make compare`` scores
it (trajectory ``<stem>.truth.csv`` beside the truth, the log's sensor reach, 0.10 m);
prints F1 (precision / recall) and the lead over OctoMap's best variant (fixed figures of
`make compare` and of the held-out runs), and the mean lead per group.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
COMPARE = Path(os.environ.get("SONARMAP_COMPARE", REPO / "build" / "compare"))
SAMPLES = Path(os.environ.get("SONARMAP_SAMPLES", REPO / "sample_logs"))
HELD = Path(os.environ.get("SONARMAP_HELD", "/tmp/q57/held"))

# (name, log, truth, OctoMap's F1 (best variant))
ROWS: list[tuple[str, Path, Path, float]] = [
    ("office", SAMPLES / "office/office.mcap", SAMPLES / "office/office.truth.yaml", 0.709),
    ("corridor", SAMPLES / "corridor/corridor.mcap", SAMPLES / "corridor/corridor.truth.yaml",
     0.656),
    ("orchard", SAMPLES / "orchard/orchard.mcap", SAMPLES / "orchard/orchard.truth.yaml", 0.482),
    ("intel", SAMPLES / "intel-lab/intel.mcap", SAMPLES / "intel-lab/intel.laser.yaml", 0.582),
    ("freiburg", COMPARE / "freiburg-101.mcap", COMPARE / "freiburg-101.laser.yaml", 0.542),
    ("orebro", COMPARE / "orebro.mcap", COMPARE / "orebro.laser.yaml", 0.507),
    ("fhw", COMPARE / "fhw.mcap", COMPARE / "fhw.laser.yaml", 0.508),
    ("belgioioso", COMPARE / "belgioioso.mcap", COMPARE / "belgioioso.laser.yaml", 0.556),
    ("office-r", COMPARE / "office-realistic.mcap", COMPARE / "office-realistic.truth.yaml",
     0.430),
    ("corridor-r", COMPARE / "corridor-realistic.mcap",
     COMPARE / "corridor-realistic.truth.yaml", 0.380),
    ("orchard-r", COMPARE / "orchard-realistic.mcap", COMPARE / "orchard-realistic.truth.yaml",
     0.238),
    ("intel-r", COMPARE / "intel-realistic.mcap", COMPARE / "intel-realistic.laser.yaml", 0.291),
    ("freiburg-r", COMPARE / "freiburg-101-realistic.mcap",
     COMPARE / "freiburg-101-realistic.laser.yaml", 0.313),
    ("orebro-r", COMPARE / "orebro-realistic.mcap", COMPARE / "orebro-realistic.laser.yaml",
     0.262),
    ("fhw-r", COMPARE / "fhw-realistic.mcap", COMPARE / "fhw-realistic.laser.yaml", 0.339),
    ("belgioioso-r", COMPARE / "belgioioso-realistic.mcap",
     COMPARE / "belgioioso-realistic.laser.yaml", 0.312),
    ("intel-c12", HELD / "intel-c12.mcap", HELD / "intel-c12.laser.yaml", 0.350),
    ("freiburg-c12", HELD / "freiburg-101-c12.mcap", HELD / "freiburg-101-c12.laser.yaml",
     0.420),
    ("orebro-c12", HELD / "orebro-c12.mcap", HELD / "orebro-c12.laser.yaml", 0.311),
    ("orebro-c30", HELD / "orebro-c30.mcap", HELD / "orebro-c30.laser.yaml", 0.363),
]
GROUPS = {
    "buildings ideal": ["intel", "freiburg", "orebro", "fhw", "belgioioso"],
    "buildings realistic": ["intel-r", "freiburg-r", "orebro-r", "fhw-r", "belgioioso-r"],
    "worlds ideal": ["office", "corridor", "orchard"],
    "worlds realistic": ["office-r", "corridor-r", "orchard-r"],
    "held out": ["intel-c12", "freiburg-c12", "orebro-c12", "orebro-c30"],
}


def parse_value(text: str) -> object:
    """A key's value from the command line: bool, int, float or text."""
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def main() -> None:
    from benchmarks.compare_methods import load_config_for, log_reach
    from pipeline.methods import Method
    from pipeline.run import run
    from pipeline.tools.evaluate import evaluate_run

    args = sys.argv[1:]
    out = Path(args.pop(0))
    only: list[str] = []
    if "--only" in args:
        k = args.index("--only")
        only, args = args[k + 1:], args[:k]
    em = False
    if "--variant" in args:
        k = args.index("--variant")
        em = args[k + 1].split(",")[0] == "em"
        if em:  # Thrun's EM iterations (benchmarks/research/em_forward.py)
            from benchmarks.research.em_forward import install
        else:
            from benchmarks.research.wall_lines_variants import install
        install(args[k + 1])
        args = args[:k] + args[k + 2:]
    overrides = {a.split("=", 1)[0]: parse_value(a.split("=", 1)[1]) for a in args}
    results: dict[str, tuple[float, float, float, float]] = {}
    per_iter: dict[str, object] = {}
    for name, log, truth, octo in ROWS:
        if only and name not in only:
            continue
        from benchmarks.research import wall_lines_variants

        wall_lines_variants.TRUTH[:] = [truth]
        cfg = load_config_for(log, None)
        mapper = dataclasses.replace(cfg.mapper, method=Method.FORWARD, **overrides)
        cfg = cfg.replace(mapper=mapper)
        run(log, out / name, cfg, force=True)
        stem = truth.name.split(".")[0]
        traj = truth.with_name(f"{stem}.truth.csv")
        ev = evaluate_run(out / name, truth, trajectory=traj if traj.is_file() else None,
                          tolerance_m=0.10, sensor_reach_m=log_reach(log, cfg))
        results[name] = (ev.f1, ev.precision, ev.recall, ev.f1 - octo)
        print(f"{name:14s} {ev.f1:.3f} ({ev.precision:.2f} / {ev.recall:.2f}) "
              f"{ev.f1 - octo:+.3f}", flush=True)
        if em:
            from benchmarks.research import em_forward

            rec = em_forward.RECORDS[-1]
            iters = em_forward.score_iterations(out / name, truth, traj if traj.is_file()
                                                else None, log_reach(log, cfg), octo)
            per_iter[name] = {"rows": iters, "changed": rec["changed"], "cpu": rec["cpu"],
                              "rho": rec["rho"], "converged": rec["converged"]}
            print("    iterations: " + "  ".join(
                f"{k}: {f:.3f} ({lead:+.3f})" for k, (f, _, _, lead) in enumerate(iters))
                + f"  changed {rec['changed']} cpu "
                + " ".join(f"{c:.1f}" for c in rec["cpu"]) + " s", flush=True)
    for group, names in GROUPS.items():
        leads = [results[n][3] for n in names if n in results]
        if leads:
            print(f"{group:20s} mean {sum(leads) / len(leads):+.3f} (worst {min(leads):+.3f})")
    (out / "rows.json").write_text(json.dumps({"overrides": overrides, "rows": results,
                                               "iterations": per_iter},
                                              indent=1))


if __name__ == "__main__":
    main()
