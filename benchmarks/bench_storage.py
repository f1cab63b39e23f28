"""A log read from object storage: ``sonarmap run`` of the one-hour log from a loopback S3
server against the same log on disk.

Usage: ``python benchmarks/bench_storage.py [--seconds 3600] [--repeat 3]
[--rss-factor 10] [--smoke]``

Input: ``bench_end_to_end``'s simulated one-hour MCAP log (cached, deterministic). It is
put into a bucket of moto's S3 server started here on 127.0.0.1 (a random port; the
server runs in this process, the runs in fresh child processes as ``bench_end_to_end``
does), then mapped ``--repeat`` times from ``s3://`` and from the file, alternately. The
figures: median wall time of each, their ratio (target ≤ 1.5×), peak RSS of each (the
remote run reads through a block cache of ``[storage] block_size_mib × cache_blocks``,
32 MiB by default, larger than the one-hour log: so the peak RSS is also measured from S3
for a ``--rss-factor``× longer log, 214 MB, the one ``bench_end_to_end`` generates for its
own RSS row; target ≤ 1.2× of 1×), and whether the two maps are byte-identical.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks.bench_end_to_end import LogSpec, RunFigures, cached_log, run_once  # noqa: E402
from benchmarks.loopback_s3 import loopback_s3  # noqa: E402


def main(argv: list[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3600.0, help="length of the log, s")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each (median reported)")
    ap.add_argument("--rss-factor", type=float, default=10.0,
                    help="peak RSS from S3 is compared between 1x and this many times longer "
                         "(0: skip)")
    ap.add_argument("--smoke", action="store_true", help="a 20 s log, one run each")
    args = ap.parse_args(argv)
    if args.smoke:
        args.seconds, args.repeat, args.rss_factor = 20.0, 1, 0.0
    log = cached_log(LogSpec(seconds=args.seconds))
    size_mb = log.stat().st_size / 1e6
    with loopback_s3(), tempfile.TemporaryDirectory(prefix="bench_storage_") as tmp:
        import fsspec

        fs = fsspec.filesystem("s3", skip_instance_cache=True)
        fs.mkdir("bench")
        fs.put_file(str(log), "bench/log.mcap")
        local: list[RunFigures] = []
        remote: list[RunFigures] = []
        for _ in range(args.repeat):  # alternately: both see the same machine load
            local.append(run_once(log, Path(tmp) / "local"))
            remote.append(run_once("s3://bench/log.mcap", Path(tmp) / "remote"))  # type: ignore[arg-type]
        same = (Path(tmp) / "local" / "map.pgm").read_bytes() == \
            (Path(tmp) / "remote" / "map.pgm").read_bytes()
        long: RunFigures | None = None
        if args.rss_factor > 1:
            long_log = cached_log(LogSpec(seconds=args.seconds * args.rss_factor))
            fs.put_file(str(long_log), "bench/long.mcap")
            long = run_once("s3://bench/long.mcap", Path(tmp) / "long")  # type: ignore[arg-type]
            fs.rm_file("bench/long.mcap")
    wall_l = statistics.median(r.wall for r in local)
    wall_r = statistics.median(r.wall for r in remote)
    rss_l = statistics.median(r.rss_mb for r in local)
    rss_r = statistics.median(r.rss_mb for r in remote)
    figures = {"size MB": size_mb, "readings": float(local[0].readings),
               "wall local s": wall_l, "wall s3 s": wall_r, "ratio": wall_r / wall_l,
               "cpu local s": statistics.median(r.cpu for r in local),
               "cpu s3 s": statistics.median(r.cpu for r in remote),
               "rss local MB": rss_l, "rss s3 MB": rss_r, "same map": float(same)}
    print(f"\nsonarmap run of a {args.seconds:g} s log ({size_mb:.1f} MB MCAP, "
          f"{local[0].readings} readings); median of {args.repeat}")
    print(f"{'source':>22} {'wall s':>7} {'CPU s':>6} {'RSS MB':>7}")
    print(f"{'local file':>22} {wall_l:>7.2f} {figures['cpu local s']:>6.2f} {rss_l:>7.0f}")
    print(f"{'loopback S3 (moto)':>22} {wall_r:>7.2f} {figures['cpu s3 s']:>6.2f} {rss_r:>7.0f}")
    print(f"S3 / local wall: {wall_r / wall_l:.2f}x (target <= 1.5x); RSS "
          f"{rss_r - rss_l:+.0f} MB; maps byte-identical: {same}")
    if long is not None:
        figures["rss s3 long MB"] = long.rss_mb
        figures["rss growth"] = long.rss_mb / rss_r
        figures["wall s3 long s"] = long.wall
        print(f"peak RSS from S3: 1x {rss_r:.0f} MB -> {args.rss_factor:g}x "
              f"{long.rss_mb:.0f} MB: {long.rss_mb / rss_r:.2f}x (target <= 1.2x); "
              f"{args.rss_factor:g}x wall {long.wall:.1f} s")
    return figures


if __name__ == "__main__":
    main()
