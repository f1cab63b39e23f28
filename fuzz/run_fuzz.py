"""The long fuzz run: thousands of mutated logs per format through the reader property.

Usage (from the repository root)::

    .venv/bin/python -m fuzz.run_fuzz --examples 2000 [--seed 0] [--target mcap] [--keep DIR]

``--examples`` is per target (a target is one valid fixture file; see
:func:`fuzz.harness.build_targets`). Prints, per format family, how many inputs were
tried, read (ok), rejected with a proper one-line FormatError/TopicError, and defects;
then each distinct defect with a reproducer (target + mutation). ``--keep DIR`` saves the
mutated input of every defect. Exit status 1 when a defect was found.
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fuzz.harness import Target, build_targets, check
from fuzz.mutators import Mutation, apply, random_mutation


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--examples", type=int, default=1000, help="mutated inputs per target")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--target", default="", help="only targets whose name contains this")
    ap.add_argument("--keep", type=Path, default=None, help="save defect inputs here")
    ap.add_argument("--side-files", type=int, default=0,
                    help="also the side-file classes (fuzz.side_files), this many random "
                         "cases per class where a class draws them")
    ap.add_argument("--values", type=int, default=0,
                    help="also this many hostile-value logs (fuzz.values) plus every "
                         "numeric config key with every hostile number")
    args = ap.parse_args(argv)

    import warnings

    # Dirty data is the point here; numpy's overflow warnings on garbage values are noise.
    warnings.simplefilter("ignore", RuntimeWarning)
    with tempfile.TemporaryDirectory(prefix="sonarmap-fuzz-") as tmp:
        targets = [t for t in build_targets(Path(tmp) / "fixtures") if args.target in t.name]
        work = Path(tmp) / "work"
        work.mkdir()
        status = _run(targets, args.examples, args.seed, work, args.keep)
        if args.values:
            status |= _run_values(args.values, args.seed, work)
        if args.side_files:
            status |= _run_side_files(args.side_files, args.seed, Path(tmp) / "side")
        return status


def _run_side_files(examples: int, seed: int, work: Path) -> int:
    """Side files and hostile numbers through the commands (fuzz.side_files)."""
    from fuzz.side_files import run_classes, table

    defects: list[str] = []
    tally = run_classes(work, seed, examples, report=defects.append)
    print()
    print(table(tally))
    for d in sorted(set(defects)):
        print(d)
    return 1 if defects else 0


def _run_values(examples: int, seed: int, work: Path) -> int:
    """Hostile numbers: every numeric config key × every HOSTILE value, then ``examples``
    small logs with hostile beam widths, limits, pose glitches and no-echo readings."""
    from fuzz.values import HOSTILE, check_config, check_log, numeric_keys

    tally: Counter[str] = Counter()
    defects: list[str] = []
    for section, key in numeric_keys():
        for value in HOSTILE:
            outcome = check_config(section, key, value)
            tally[f"config {outcome.status}"] += 1
            if outcome.status == "defect":
                defects.append(outcome.detail)
    rnd = random.Random(f"{seed}:values")
    for i in range(examples):
        outcome = check_log(work, rnd, i)
        tally[f"log {outcome.status}"] += 1
        if outcome.status == "defect":
            defects.append(outcome.detail)
    print()
    print("hostile values: " + ", ".join(f"{k} {v}" for k, v in sorted(tally.items())))
    for d in sorted(set(defects)):
        print(f"DEFECT: {d}")
    return 1 if defects else 0


def _run(targets: list[Target], examples: int, seed: int, work: Path, keep: Path | None) -> int:
    per_family: dict[str, Counter[str]] = defaultdict(Counter)
    defects: dict[str, list[tuple[str, Mutation]]] = defaultdict(list)
    started = time.perf_counter()
    for target in targets:
        data = target.valid_bytes()
        points = target.points()
        rnd = random.Random(f"{seed}:{target.name}")
        t0 = time.perf_counter()
        local: Counter[str] = Counter()
        for i in range(examples):
            m = random_mutation(rnd, data, points, target.text)
            mutated = apply(data, m)
            outcome = check(target, mutated, work)
            local[outcome.status] += 1
            local["read"] += outcome.status in ("ok", "loss")
            if outcome.defect:
                defects[outcome.detail[:160]].append((target.name, m))
                if keep is not None:
                    keep.mkdir(parents=True, exist_ok=True)
                    (keep / f"{target.name}-{i}{target.file.suffix}").write_bytes(mutated)
        per_family[target.family].update(local)
        per_family[target.family]["tried"] += examples
        print(
            f"{target.name:<38} {examples:>6} tried {local['ok']:>6} ok {local['loss']:>6} loss "
            f"{local['rejected']:>6} rejected {local['defect']:>4} defects "
            f"({time.perf_counter() - t0:.1f} s)",
            flush=True,
        )
    print()
    print(f"{'format':<8} {'tried':>8} {'ok':>8} {'loss':>8} {'rejected':>9} {'defects':>8}")
    for family in sorted(per_family):
        c = per_family[family]
        print(f"{family:<8} {c['tried']:>8} {c['ok']:>8} {c['loss']:>8} {c['rejected']:>9}"
              f" {c['defect']:>8}")
    total = sum(c["tried"] for c in per_family.values())
    print(f"{total} inputs in {time.perf_counter() - started:.0f} s; "
          f"{len(defects)} distinct defects")
    for detail, hits in sorted(defects.items()):
        name, m = hits[0]
        print(f"DEFECT x{len(hits)}: {detail}\n    reproduce: target {name}, {m.describe()}")
    return 1 if defects else 0


if __name__ == "__main__":
    sys.exit(main())
