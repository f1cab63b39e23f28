"""Mutation score on a seeded random sample of mutants (``make mutate``).

mutmut 3 mutates the modules ``[tool.mutmut] only_mutate`` in pyproject.toml names (the
mapper, pose sync, scan building, the nav2 map writer/loader) and runs each mutant against
the tests that executed the mutated function. Every mutant takes hours on two cores; this
runs a sample:

1. ``mutmut run`` with a pattern matching no mutant: generates every mutant and the table
   of which tests reach which function (mutmut refuses the empty selection afterwards);
2. draws ``--sample`` mutant names with ``random.Random(--seed)`` from the sorted list;
3. ``mutmut run --max-children N`` on those names;
4. prints, per module, killed / survived / timeout / no tests, the score
   ``(killed + timeout) / (killed + timeout + survived)`` and the survivors (``mutmut show
   NAME`` prints one; equivalent ones are listed in the README's Development section).

Usage: ``python -m benchmarks.mutation_sample [--sample 150] [--seed 13] [--children 2]``
(run from the repository root; ``mutants/`` is mutmut's working directory).
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MUTANTS = ROOT / "mutants"
MUTMUT = [sys.executable, "-m", "mutmut"]
NO_MUTANT = "sonarmap-matches-no-mutant"
# mutmut's exit-code verdicts (mutmut.stats.status_by_exit_code), the ones a run gives.
STATUS = {1: "killed", 3: "killed", 0: "survived", 5: "no tests", 33: "no tests",
          36: "timeout", 24: "timeout", -24: "timeout", 152: "timeout", 255: "timeout"}


def all_mutants() -> dict[str, int | None]:
    """Every generated mutant's name and its exit code (None: not run)."""
    out: dict[str, int | None] = {}
    for meta in sorted(MUTANTS.rglob("*.meta")):
        out.update(json.loads(meta.read_text(encoding="utf-8"))["exit_code_by_key"])
    return out


def module_of(name: str) -> str:
    """``pipeline.stages.scans.x_ScanKeys__mutmut_3`` → ``pipeline.stages.scans``."""
    head = name.split("__mutmut_")[0]
    return ".".join(p for p in head.split(".") if not p.startswith(("x_", "xǁ")))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sample", type=int, default=150, help="mutants to run")
    ap.add_argument("--seed", type=int, default=13, help="seed of the draw")
    ap.add_argument("--children", type=int, default=2, help="mutants run at once")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    shutil.rmtree(MUTANTS, ignore_errors=True)
    log = ROOT / "mutmut.log"  # mutmut's own output, for when something goes wrong
    with log.open("w", encoding="utf-8") as out:
        subprocess.run([*MUTMUT, "run", NO_MUTANT], cwd=ROOT, check=False, stdout=out,
                       stderr=subprocess.STDOUT)
    names = sorted(all_mutants())
    if not names:
        print(f"mutmut generated no mutants (its output: {log})", file=sys.stderr)
        return 1
    sample = sorted(random.Random(args.seed).sample(names, min(args.sample, len(names))))
    print(f"{len(names)} mutants generated; running {len(sample)} (seed {args.seed})",
          flush=True)
    with log.open("a", encoding="utf-8") as out:
        subprocess.run([*MUTMUT, "run", "--max-children", str(args.children), *sample],
                       cwd=ROOT, check=False, stdout=out, stderr=subprocess.STDOUT)
    codes = all_mutants()
    verdict = {n: STATUS.get(codes.get(n), "other") for n in sample}  # type: ignore[arg-type]
    per_module: dict[str, Counter[str]] = {}
    for n, v in verdict.items():
        per_module.setdefault(module_of(n), Counter())[v] += 1
    total: Counter[str] = Counter(verdict.values())
    cols = ("killed", "timeout", "survived", "no tests", "other")
    print(f"\n{'module':<40}" + "".join(f"{c:>10}" for c in cols) + f"{'score':>8}")
    for mod, c in [*sorted(per_module.items()), ("all", total)]:
        done = c["killed"] + c["timeout"] + c["survived"]
        score = f"{100 * (c['killed'] + c['timeout']) / done:.0f} %" if done else "-"
        print(f"{mod:<40}" + "".join(f"{c[k]:>10}" for k in cols) + f"{score:>8}")
    print("\nsurvivors (mutmut show NAME):")
    for n, v in verdict.items():
        if v == "survived":
            print(f"  {n}")
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
