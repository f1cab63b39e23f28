"""Where a run's time goes, pass by pass (docs/PERFORMANCE.md §1).

Usage: ``python -m benchmarks.research.pass_profile LOG OUT [--threads 1|2]``

Runs ``pipeline.run.run`` in this process on LOG (the default configuration) and prints,
for every mapping pass, its wall seconds, the CPU seconds of the process and of the main
thread, and the thread CPU seconds of each compiled kernel called in it (summed over the
threads that called it). Main-thread CPU minus its kernels is the pass's numpy and
Python work. The kernels are wrapped where the mappers call them; results are unchanged.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import resource
import time
from collections.abc import Callable
from typing import Any

import pipeline.mapper.andersone as andersone
import pipeline.mapper.attribution as attribution
import pipeline.mapper.forward as forward
import pipeline.mapper.specular as specular
import pipeline.run as run_module
from pipeline.config import Config
from pipeline.mapper.kernels.warm import warm

KERNELS = (
    (attribution, ("count_free", "count_arcs", "attribute_echoes", "cone_table")),
    (specular, ("trace_readings", "shadow_profiles", "cone_table", "echo_candidate_lists",
                "spread_candidate_lists")),
    (forward, ("detection_counts", "cone_table", "vote_tangents", "wall_lines", "near_lines",
               "fit_detection")),
    (andersone, ("free_unions", "add_free_unions", "reading_features")),
    (andersone.andersone_scans, ("integrate_scans",)),
)


def main(argv: list[str] | None = None) -> None:
    """Profile one run (module doc)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log")
    parser.add_argument("out")
    parser.add_argument("--threads", type=int, default=2, choices=(1, 2))
    args = parser.parse_args(argv)
    seconds: dict[tuple[str, str], float] = collections.defaultdict(float)
    current = ["setup"]

    def timed(fn: Callable[..., Any], name: str) -> Callable[..., Any]:
        def call(*a: Any, **k: Any) -> Any:
            t = time.thread_time()
            try:
                return fn(*a, **k)
            finally:
                seconds[(current[0], name)] += time.thread_time() - t
        return call

    for module, names in KERNELS:
        for name in names:
            setattr(module, name, timed(getattr(module, name), name))
    run_module._sync = timed(run_module._sync, "pose sync")  # type: ignore[attr-defined]
    mark: dict[str, float] = {}

    def close() -> None:
        if mark:
            p = current[0]
            seconds[(p, "PASS main-thread CPU")] += time.thread_time() - mark["thread"]
            seconds[(p, "PASS process CPU")] += time.process_time() - mark["process"]
            seconds[(p, "PASS wall")] += time.perf_counter() - mark["wall"]
            mark.clear()

    make = run_module.make_mapper

    def make_timed(*a: Any, **k: Any) -> Any:
        mapper = make(*a, **k)
        begin, snapshot = mapper.begin_pass, mapper.snapshot

        def begin_pass(index: int) -> None:
            close()
            current[0] = f"pass {index}"
            mark.update(thread=time.thread_time(), process=time.process_time(),
                        wall=time.perf_counter())
            begin(index)

        def snap() -> Any:
            close()
            current[0] = "snapshot"
            return snapshot()

        mapper.begin_pass, mapper.snapshot = begin_pass, snap
        return mapper

    run_module.make_mapper = make_timed  # type: ignore[assignment]
    config = Config()
    config = dataclasses.replace(config, mapper=dataclasses.replace(config.mapper,
                                                                    threads=args.threads))
    warm()
    t, p = time.perf_counter(), time.process_time()
    result = run_module.run(args.log, args.out, config, force=True)
    print(f"run: {time.perf_counter() - t:.2f} s wall, {time.process_time() - p:.2f} s CPU, "
          f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    print("stages:", result.metrics.timing["stage_seconds"])
    for (part, name), value in sorted(seconds.items()):
        print(f"{part:>10}  {name:<22} {value:7.3f}")


if __name__ == "__main__":
    main()
