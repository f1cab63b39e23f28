"""One recording in several files: what reading the files as one costs, against the whole.

Usage: ``python benchmarks/bench_several_files.py [--seconds 3600] [--splits 6] [--repeat 1]
[--smoke]``

Input: the simulated one-hour MCAP log of ``bench_end_to_end`` (cached), cut like recorders
cut it — by time into ``--splits`` consecutive files (``rosbag record --split``) and by topic
into a sonar and an odometry file (overlapping over the whole hour) — with the ``mcap``
library (every message copied with its log time and bytes). Each is mapped by ``sonarmap
run`` in a fresh process; the table gives wall seconds, the ingest stage's seconds (where
the merge happens), the process's CPU seconds (other jobs on the machine inflate wall
time, not these), peak RSS and whether ``map.pgm`` is byte-identical to the whole log's.
The merge is lazy (one chunk per file in memory), so peak RSS should not grow with the
number of files.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

if __package__ in (None, ""):  # run as a script: the repository root on the path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_end_to_end import LogSpec, RunFigures, cached_log, run_once
from benchmarks.log_parts import Accept, anything, split_mcap


def _cut(src: Path, parts: Sequence[tuple[Path, Accept]]) -> None:
    """Copy every message of ``src`` into the first part that accepts it (zstd chunks);
    every message must land in a part."""
    from mcap.reader import make_reader

    split_mcap(src, parts)

    def count(p: Path) -> int:
        with p.open("rb") as f:
            return int(make_reader(f).get_summary().statistics.message_count)  # type: ignore[union-attr]

    if sum(count(p) for p, _ in parts) != count(src):
        raise AssertionError(f"no part takes some messages of {src}")


def split_files(log: Path, splits: int) -> dict[str, list[Path]]:
    """The log cut by time into ``splits`` files and by topic into two (cached beside it)."""
    from mcap.reader import make_reader

    d = log.parent / f"parts-v3-{splits}"
    by_time = [d / f"rec_{i}.mcap" for i in range(splits)]
    by_topic = [d / "sonar.mcap", d / "odom.mcap"]
    if not all(p.exists() for p in by_time + by_topic):
        d.mkdir(exist_ok=True)
        with log.open("rb") as f:
            stats = make_reader(f).get_summary().statistics  # type: ignore[union-attr]
        t0, t1 = stats.message_start_time, stats.message_end_time + 1

        def before(k: int) -> Accept:  # integer ns: exact cuts
            return lambda topic, t, data: t < t0 + (k + 1) * (t1 - t0) // splits

        _cut(log, [(p, before(k)) for k, p in enumerate(by_time)])
        pose_topics = {"/odom", "/tf"}
        _cut(log, [(by_topic[0], lambda topic, t, data: topic not in pose_topics),
                   (by_topic[1], anything())])
    return {f"by time, {splits} files": by_time, "by topic, sonar + odometry": by_topic}


def _run(paths: list[Path], out: Path, repeat: int) -> RunFigures:
    runs = sorted((run_once(paths[0], out, tuple(map(str, paths[1:]))) for _ in range(repeat)),
                  key=lambda r: r.wall)
    return runs[(len(runs) - 1) // 2]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3600.0)
    ap.add_argument("--splits", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--smoke", action="store_true", help="60 s of log, 3 splits")
    args = ap.parse_args(argv)
    seconds, splits = (60.0, 3) if args.smoke else (args.seconds, args.splits)
    log = cached_log(LogSpec(seconds=seconds))
    cases = {"whole log, 1 file": [log], **split_files(log, splits)}
    with tempfile.TemporaryDirectory(prefix="bench_files_") as tmp:
        figures = {name: _run(paths, Path(tmp) / f"out{i}", args.repeat)
                   for i, (name, paths) in enumerate(cases.items())}
        whole_map = (Path(tmp) / "out0" / "map.pgm").read_bytes()
        same = {name: (Path(tmp) / f"out{i}" / "map.pgm").read_bytes() == whole_map
                for i, name in enumerate(cases)}
    print(f"# {seconds:g} s log, {figures['whole log, 1 file'].readings} readings; "
          f"median of {args.repeat}")
    print("| input | wall (s) | CPU (s) | ingest (s) | peak RSS (MiB) | map.pgm as the whole's |")
    print("|---|---:|---:|---:|---:|---|")
    for name, r in figures.items():
        print(f"| {name} | {r.wall:.1f} | {r.cpu:.1f} | {r.stages['ingest']:.1f} | "
              f"{r.rss_mb:.0f} | {'identical' if same[name] else 'DIFFERENT'} |")


if __name__ == "__main__":
    main()
