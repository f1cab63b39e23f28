"""``python -m benchmarks``: every benchmark in one run, one table, written to RESULTS.md.

Usage: ``python -m benchmarks [--quick] [--smoke] [--only readers mapper e2e batch regress storage]
[--results PATH | --no-results]``

Inputs are generated deterministically (no downloads): the reader bags by
``bench_readers`` / ``bench_readers_ros2`` (~500k messages), the mapper's synthetic room
by ``bench_mapper`` (~100k readings at 0.05 m), the simulated one-hour MCAP log by
``bench_end_to_end`` (cached under the system temp dir), the batch's CSV logs by
``bench_batch``; the storage section reads the one-hour log from a loopback S3 server
(moto, 127.0.0.1). The mapper section also reports the compiled kernels' one-off cost
(compiling on a machine's first run; loading from numba's cache after). Every ratio is of two figures
measured side by side in this run. ``--quick`` skips the 10× memory runs and repeats
nothing; ``--smoke`` runs everything on tiny inputs (seconds; for the test suite) and
writes no RESULTS.md unless ``--results`` is given.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import platform
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from benchmarks import (
    bench_batch,
    bench_end_to_end,
    bench_mapper,
    bench_readers,
    bench_readers_ros2,
    bench_regress_suite,
    bench_storage,
)

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
SECTIONS = ("readers", "mapper", "e2e", "batch", "regress", "storage")
NOTES_MARKER = "<!-- analysis: kept when the table above is regenerated -->"


@dataclass
class Row:
    """One line of the table: a figure, its unit, and a ratio against a target."""

    section: str
    case: str
    value: float
    unit: str
    ratio: str = ""
    target: str = ""
    met: bool | None = None


def _quiet(fn: object, *args: object, verbose: bool) -> object:
    """Call ``fn(*args)``; its own printout goes to stderr-free oblivion unless verbose."""
    if verbose:
        return fn(*args)  # type: ignore[operator]
    with contextlib.redirect_stdout(io.StringIO()):
        return fn(*args)  # type: ignore[operator]


def readers_rows(smoke: bool, quick: bool, verbose: bool) -> list[Row]:
    """ROS 1 (uncompressed, lz4) and ROS 2 MCAP: sonarmap vs rosbags, messages/s."""
    argv = ["--smoke"] if smoke else []
    if quick or smoke:
        argv.append("--no-rss")
    f1 = _quiet(bench_readers.main, argv, verbose=verbose)
    f2 = _quiet(bench_readers_ros2.bench_mcap_ros2, smoke, verbose=verbose)
    assert isinstance(f1, dict) and isinstance(f2, dict)
    rows: list[Row] = []
    for bag in bench_readers.BAG_MAKERS:
        n = f1[f"messages {bag} / sonarmap RosLogReader"]
        speed = f1[f"speedup {bag}"]
        rate = f1[f"rate {bag} / sonarmap RosLogReader"]
        rows.append(Row("readers", f"{bag}: {int(n)} msgs, sonarmap", rate, "msg/s",
                        f"{speed:.1f}x rosbags", ">= 10x", speed >= 10))
        rows.append(Row("readers", f"{bag}: rosbags AnyReader+deserialize",
                        f1[f"rate {bag} / rosbags AnyReader+deserialize"], "msg/s"))
    rows.append(Row("readers", f"ros2 mcap: {int(f2['messages'])} msgs, sonarmap", f2["sonarmap"],
                    "msg/s", f"{f2['speedup']:.1f}x rosbags", ">= 10x", f2["speedup"] >= 10))
    rows.append(Row("readers", "ros2 mcap: rosbags AnyReader+deserialize", f2["rosbags"], "msg/s"))
    if "rss growth" in f1:
        g = f1["rss growth"]
        rows.append(Row("readers", "ros1 lz4 reader peak RSS, 10x bag", f1["rss 10x MB"], "MB",
                        f"{g:.2f}x of 1x", "<= 1.2x", g <= 1.2))
    return rows


def mapper_rows(smoke: bool, quick: bool, verbose: bool) -> list[Row]:
    """The three methods and OctoMap on the same readings at 0.05 m, readings/s."""
    argv = ["--readings-per-scan", "32"] + (["--smoke"] if smoke else [])
    if not (smoke or quick):
        argv += ["--repeat", "3"]
    f = _quiet(bench_mapper.main, argv, verbose=verbose)
    assert isinstance(f, dict)
    octo = f.get("octomap")
    n = int(f["readings"])
    rows: list[Row] = []
    for name, label in (
        ("forward (default, §11)",
         "default method (specular echo attribution, detection measured, 5 passes)"),
        ("specular (§10)", "specular echo attribution (§10, 4 passes)"),
        ("attribution", "echo attribution (§9, 2 passes)"),
        ("andersone+correction", "paper's method (correction on)"),
        ("andersone", "without correction"),
        ("classic", "classic log-odds baseline"),
    ):
        rate = f[f"{name} 32/scan"]
        if octo:
            # Side by side in wall time (the target) and in CPU time (robust to other jobs).
            cpu_ratio = f[f"{name} 32/scan cpu"] / f["octomap cpu"]
            goal = 20 if name == "classic" else 10
            rows.append(Row("mapper", f"{n} readings, {label}", rate, "readings/s",
                            f"{rate / octo:.2f}x octomap ({cpu_ratio:.2f}x per CPU s)",
                            f">= {goal}x", rate / octo >= goal))
        else:
            rows.append(Row("mapper", f"{n} readings, {label}", rate, "readings/s"))
    if octo:
        rows.append(Row("mapper", "OctoMap (octomap-python, cone fans)", octo, "readings/s"))
    if "warm cold s" in f:
        rows.append(Row("mapper", "kernels: compile, a machine's first run (cold cache)",
                        f["warm cold s"], "s once",
                        f"process CPU {f['process cpu cold s']:.1f} s; then cached on disk"))
        rows.append(Row("mapper", "kernels: load from the cache, every later process",
                        f["warm cached s"], "s per run",
                        f"+ {f['import cached s']:.2f} s imports; process CPU "
                        f"{f['process cpu cached s']:.1f} s"))
    return rows


@dataclass(frozen=True)
class _Affine:
    """Wall time as a fixed part per process plus a part per log length: ``a + b·x`` (x in
    multiples of the 1× log), least squares over every size measured."""

    a: float
    b: float

    def text(self, x: float) -> str:
        return f"fit {self.a:.2f} s + {self.b:.2f} s per 1x = {self.a + self.b * x:.2f} s"

    def ok(self, x: float, wall: float) -> bool:
        """Within 15 % of the fit: time grows linearly with the log (the fixed part —
        imports, numba's set-up, the outputs' floor — is not growth)."""
        return abs(wall - (self.a + self.b * x)) <= 0.15 * (self.a + self.b * x)


def _affine_fit(f: dict[str, float], fracs: list[float]) -> _Affine:
    import numpy as np

    sizes = sorted({*fracs, 1.0, *(float(k.split()[1][:-1]) for k in f
                                   if k.startswith("wall ") and k.endswith("x s"))})
    xs = np.array(sizes)
    ys = np.array([f[f"wall {x:g}x s"] for x in sizes])
    if xs.size < 2:
        return _Affine(0.0, float(ys[0]) if ys.size else 0.0)
    b, a = np.polyfit(xs, ys, 1)
    return _Affine(float(a), float(b))


def e2e_rows(smoke: bool, quick: bool, verbose: bool) -> list[Row]:
    """``sonarmap run`` on the one-hour log (stage shares) and its 1/4, 1/2 scaling."""
    argv = ["--smoke"] if smoke else (["--repeat", "1", "--rss-factor", "0"] if quick else [])
    f = _quiet(bench_end_to_end.main, argv, verbose=verbose)
    assert isinstance(f, dict)
    fracs = sorted(float(k.split()[1][:-1]) for k in f if k.startswith("wall ") and
                   k.endswith("x s") and f"readings {k.split()[1]}" in f)
    rows: list[Row] = []
    one = f["wall 1x s"]
    n1 = int(f["readings 1x"])
    target = 8.0 if not smoke else float("inf")
    rows.append(Row("e2e", f"sonarmap run, 1x log ({n1} readings, MCAP zstd)", one, "s wall",
                    f"{n1 / one:.0f} readings/s; {f['cpu 1x s']:.1f} s CPU", "< 8 s",
                    one < target))
    for stage in (*bench_end_to_end.STAGES, "outputs+startup"):
        rows.append(Row("e2e", f"  share: {stage}", 100 * f[f"share {stage} 1x"], "% of wall"))
    refined = f["refined wall 1x s"]
    rows.append(Row("e2e", "sonarmap run --refine-poses, 1x log", refined, "s wall",
                    f"{f['refined cpu 1x s']:.1f} s CPU, {f['refined cpu 1x s'] / f['cpu 1x s']:.2f}x "
                    "the unrefined CPU", "< 30 s", refined < (30.0 if not smoke else float("inf"))))
    fit = _affine_fit(f, fracs)
    for frac in fracs:
        if frac == 1.0:
            continue
        key = f"{frac:g}x"
        w = f[f"wall {key} s"]
        rows.append(Row("scaling", f"{key} log ({int(f[f'readings {key}'])} readings)", w, "s wall",
                        f"1x/{key} = {one / w:.2f} (proportional {1 / frac:g}); {fit.text(frac)}; "
                        f"CPU {f[f'cpu {key} s']:.1f} s (1x/{key} "
                        f"{f['cpu 1x s'] / f[f'cpu {key} s']:.2f}); "
                        f"peak RSS {f[f'rss {key} MB']:.0f} MB", "~linear", fit.ok(frac, w)))
    rows.append(Row("scaling", "1x log peak RSS", f["rss 1x MB"], "MB"))
    if "rss growth" in f:
        big = next(k for k in f if k.startswith("rss ") and k not in ("rss 1x MB", "rss growth")
                   and not any(k == f"rss {x:g}x MB" for x in fracs))
        factor = big.split()[1]
        w = f[f"wall {factor} s"]
        x = float(factor[:-1])
        rows.append(Row("scaling", f"{factor} log", w, "s wall",
                        f"{factor}/1x = {w / one:.2f} (proportional {factor[:-1]}); "
                        f"{fit.text(x)}; CPU {f[f'cpu {factor} s']:.1f} s "
                        f"({f[f'cpu {factor} s'] / f['cpu 1x s']:.2f})",
                        "~linear", fit.ok(x, w)))
        g = f["rss growth"]
        rows.append(Row("scaling", f"{factor} log peak RSS", f[big], "MB",
                        f"{g:.2f}x of 1x", "<= 1.2x", g <= 1.2))
    return rows


def batch_rows(smoke: bool, quick: bool, verbose: bool) -> list[Row]:
    """``sonarmap batch`` over 8 logs on 1 and 2 local workers: the speed-up."""
    f = _quiet(bench_batch.main, ["--smoke"] if smoke else [], verbose=verbose)
    assert isinstance(f, dict)
    speed = f["speedup"]
    return [
        Row("batch", f"{int(f['logs'])} logs x {int(f['readings'])} readings, 1 worker",
            f["wall 1"], "s wall"),
        Row("batch", "2 workers", f["wall 2"], "s wall", f"{speed:.2f}x of 1 worker", ">= 1.8x",
            speed >= 1.8 if not smoke else None),
    ]


def regress_rows(smoke: bool, quick: bool, verbose: bool) -> list[Row]:
    """``regress --suite`` of the sample logs beside ``batch`` of them, 2 workers each."""
    argv = ["--smoke"] if smoke else (["--repeat", "1"] if quick else [])
    f = _quiet(bench_regress_suite.main, argv, verbose=verbose)
    assert isinstance(f, dict)
    ratio = f["ratio"]
    return [
        Row("regress", f"sonarmap batch, {int(f['logs'])} sample logs, 2 workers", f["batch"],
            "s wall", f"{f['batch cpu']:.1f} s CPU"),
        Row("regress", "regress --suite, same logs (F1 with truths), 2 workers", f["suite"],
            "s wall", f"{f['suite cpu']:.1f} s CPU ({f['cpu ratio']:.2f}x); {ratio:.2f}x batch",
            "<= 1.2x", ratio <= 1.2 if not smoke else None),
    ]


def storage_rows(smoke: bool, quick: bool, verbose: bool) -> list[Row]:
    """The one-hour log mapped from a loopback S3 server (moto) against the local file."""
    argv = ["--smoke"] if smoke else (["--repeat", "1", "--rss-factor", "0"] if quick else [])
    f = _quiet(bench_storage.main, argv, verbose=verbose)
    assert isinstance(f, dict)
    ratio = f["ratio"]
    rows = [
        Row("storage", f"sonarmap run, 1x log on disk ({f['size MB']:.0f} MB MCAP)",
            f["wall local s"], "s wall"),
        Row("storage", "same log from loopback S3 (moto), ranged reads", f["wall s3 s"],
            "s wall", f"{ratio:.2f}x of disk", "<= 1.5x", ratio <= 1.5 if not smoke else None),
        Row("storage", "peak RSS from S3, 1x log", f["rss s3 MB"], "MB",
            f"{f['rss s3 MB'] - f['rss local MB']:+.0f} MB of disk"),
        Row("storage", "map from S3 byte-identical to the map from disk", f["same map"],
            "1 = yes", "", "1", f["same map"] == 1.0),
    ]
    if "rss growth" in f:
        g = f["rss growth"]
        rows.append(Row("storage", "peak RSS from S3, 10x log (bounded block cache)",
                        f["rss s3 long MB"], "MB", f"{g:.2f}x of 1x", "<= 1.2x",
                        g <= 1.2 if not smoke else None))
    return rows


def machine() -> str:
    """CPU model, cores, OS, Python and numpy versions."""
    import numpy

    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return (f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, numpy {numpy.__version__}")


def format_table(rows: list[Row]) -> str:
    """The rows as a Markdown table."""
    out = ["| section | case | figure | unit | ratio | target | met |",
           "|---|---|---:|---|---|---|---|"]
    for r in rows:
        v = f"{r.value:,.0f}" if abs(r.value) >= 100 else f"{r.value:.2f}"
        met = "" if r.met is None else ("yes" if r.met else "**no**")
        out.append(f"| {r.section} | {r.case} | {v} | {r.unit} | {r.ratio} | {r.target} | {met} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> list[Row]:
    """Run the selected benchmarks, print the table, write RESULTS.md; returns the rows."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=SECTIONS, default=list(SECTIONS))
    ap.add_argument("--quick", action="store_true", help="no 10x memory runs, no repeats")
    ap.add_argument("--smoke", action="store_true", help="tiny inputs (the test suite's run)")
    ap.add_argument("--results", type=Path, help="write the table here (default: RESULTS.md)")
    ap.add_argument("--no-results", action="store_true", help="do not write a results file")
    ap.add_argument("-v", "--verbose", action="store_true", help="show each benchmark's output")
    args = ap.parse_args(argv)
    makers = {"readers": readers_rows, "mapper": mapper_rows, "e2e": e2e_rows,
              "batch": batch_rows, "regress": regress_rows, "storage": storage_rows}
    rows: list[Row] = []
    t0 = time.perf_counter()
    load_before = os.getloadavg()[0]
    for name in SECTIONS:
        if name in args.only:
            print(f"# running {name} ...", file=sys.stderr, flush=True)
            rows += makers[name](args.smoke, args.quick, args.verbose)
    table = format_table(rows)
    took = time.perf_counter() - t0
    load = f"load average {load_before:.1f} at the start, {os.getloadavg()[0]:.1f} at the end"
    print(table)
    print(f"\n{machine()}; {took:.0f} s; {load}")
    path = args.results or (None if (args.smoke or args.no_results) else RESULTS)
    if path is not None and not args.no_results:
        write_results(path, table, took, args, load)
        print(f"wrote {path}")
    return rows


def write_results(path: Path, table: str, took: float, args: argparse.Namespace,
                  load: str = "") -> None:
    """RESULTS.md: the table, the machine and how it was made."""
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    mode = "smoke" if args.smoke else ("quick" if args.quick else "full")
    # Everything below the marker (the analysis) is kept when the table is rewritten.
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    notes = old[old.index(NOTES_MARKER):] if NOTES_MARKER in old else NOTES_MARKER + "\n"
    path.write_text(
        "# Benchmark results\n\n"
        f"Generated by `python -m benchmarks` ({mode} run, {', '.join(args.only)}; "
        f"{took:.0f} s) on {stamp}; {load} (2 cores shared with other jobs: wall time also "
        "measures them, CPU time much less).\n\n"
        f"Machine: {machine()}.\n\n"
        f"{table}\n\n{notes}",
        encoding="utf-8",
    )


if __name__ == "__main__":
    main()
