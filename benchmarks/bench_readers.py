"""Reader throughput and memory: sonarmap's ROS readers against rosbags' generic reader.

Generates (deterministically, into a temporary directory) a ROS 1 bag of 16 Range sonars
at 10 Hz each plus Odometry at 50 Hz (~500k messages; uncompressed and lz4) with rosbags'
writer, then prints one row per (bag, reader): messages and messages/s, and the speed-up
of our reader (all Range + Odometry batches through RosLogReader) over
``rosbags.highlevel.AnyReader`` + ``deserialize`` of every message (target ≥ 10×).
Then the peak RSS of our reader reading a 1× and a 10× bag, each in its own subprocess
(target: ≤ 1.2× growth, i.e. memory bounded by the chunk size, not the log size).

More formats add entries to ``READERS`` (a name and a function path → messages read) and
``BAG_MAKERS``; the table prints whatever is registered.

    .venv/bin/python benchmarks/bench_readers.py            # ~500k messages
    .venv/bin/python benchmarks/bench_readers.py --smoke    # tiny, for the unit test
"""

from __future__ import annotations

import argparse
import resource
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

N_SONARS = 16
SONAR_HZ = 10
ODOM_HZ = 50
NS = 1_000_000_000
T0 = 1_700_000_000 * NS


# --------------------------------------------------------------------------- bag making


def _header(seq: int, t_ns: int, frame: bytes) -> bytes:
    return struct.pack("<III", seq, t_ns // NS, t_ns % NS) + struct.pack("<I", len(frame)) + frame


def _range_bytes(seq: int, t_ns: int, frame: bytes, rng: float) -> bytes:
    return _header(seq, t_ns, frame) + struct.pack("<Bffff", 0, 0.5, 0.02, 4.0, rng)


_COV = struct.pack("<36d", *([0.0] * 36))


def _odom_bytes(seq: int, t_ns: int, x: float, y: float, yaw_half: tuple[float, float]) -> bytes:
    sz, cz = yaw_half
    return (
        _header(seq, t_ns, b"odom")
        + struct.pack("<I", 9)
        + b"base_link"
        + struct.pack("<7d", x, y, 0.0, 0.0, 0.0, sz, cz)
        + _COV
        + struct.pack("<6d", 0.1, 0.0, 0.0, 0.0, 0.0, 0.05)
        + _COV
    )


def make_ros1_bag(path: Path, seconds: float, compression: str) -> int:
    """Write the benchmark bag; returns its message count. Same arguments, same bytes."""
    import math

    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    writer = Writer(path)
    if compression == "lz4":
        writer.set_compression(Writer.CompressionFormat.LZ4)
    frames = [f"sonar_{i:02d}_link".encode() for i in range(N_SONARS)]
    sonar_dt = NS // (SONAR_HZ * N_SONARS)  # the ring fires one transducer at a time
    odom_dt = NS // ODOM_HZ
    n_sonar = int(seconds * SONAR_HZ * N_SONARS)
    n_odom = int(seconds * ODOM_HZ)
    count = 0
    with writer:
        rc = writer.add_connection("/sonar", "sensor_msgs/msg/Range", typestore=store)
        oc = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        i = k = 0
        while i < n_sonar or k < n_odom:
            ts, to = i * sonar_dt, k * odom_dt
            if i < n_sonar and (k >= n_odom or ts <= to):
                t = T0 + ts
                rng = 0.3 + (i * 7919 % 3700) / 1000.0
                writer.write(rc, t, _range_bytes(i, t - 1_000_000, frames[i % N_SONARS], rng))
                i += 1
            else:
                t = T0 + to
                yaw = 0.001 * k
                half = (math.sin(yaw / 2), math.cos(yaw / 2))
                writer.write(oc, t, _odom_bytes(k, t, 0.01 * k, 0.002 * k, half))
                k += 1
            count += 1
    return count


BAG_MAKERS: dict[str, Callable[[Path, float], int]] = {
    "ros1 uncompressed": lambda p, s: make_ros1_bag(p, s, "none"),
    "ros1 lz4": lambda p, s: make_ros1_bag(p, s, "lz4"),
}


# --------------------------------------------------------------------------- readers


def read_sonarmap(path: Path) -> int:
    """Messages read by our reader: every Range reading and Odometry pose."""
    from formats.contract import PoseBatch, RangeBatch
    from formats.ros.ros1bag import open_ros1_bag

    n = 0
    with open_ros1_bag(path) as reader:
        for b in reader.batches(("ranges", "poses")):
            if isinstance(b, (RangeBatch, PoseBatch)):
                n += len(b)
    return n


def read_rosbags(path: Path) -> int:
    """Messages read by rosbags' AnyReader, each deserialized."""
    from rosbags.highlevel import AnyReader

    n = 0
    with AnyReader([path]) as reader:
        for conn, _t, data in reader.messages():
            reader.deserialize(data, conn.msgtype)
            n += 1
    return n


READERS: dict[str, Callable[[Path], int]] = {
    "sonarmap RosLogReader": read_sonarmap,
    "rosbags AnyReader+deserialize": read_rosbags,
}


# --------------------------------------------------------------------------- measuring


@dataclass
class Row:
    bag: str
    reader: str
    messages: int
    seconds: float

    @property
    def rate(self) -> float:
        return self.messages / self.seconds if self.seconds > 0 else float("inf")


def _time(fn: Callable[[Path], int], path: Path) -> tuple[int, float]:
    """Messages read and the best wall time of up to 3 runs (runs past 2 s are not
    repeated): the machine is shared, the minimum is the least disturbed run."""
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        n = fn(path)
        best = min(best, time.perf_counter() - t)
        if best > 2.0:
            break
    return n, best


def peak_rss_mb(path: Path) -> float:
    """Peak RSS (MB) of a fresh Python process reading ``path`` with our reader."""
    out = subprocess.run(
        [sys.executable, __file__, "--rss-child", str(path)],
        check=True,
        capture_output=True,
        text=True,
    )
    return float(out.stdout.strip().splitlines()[-1])


def _rss_child(path: Path) -> None:
    read_sonarmap(path)
    # VmHWM, not ru_maxrss: ru_maxrss of a child also counts the parent's pages it had
    # between fork and exec, so a big parent inflates it. Both are in KiB.
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            hwm = next(line for line in f if line.startswith("VmHWM:"))
        print(int(hwm.split()[1]) / 1024.0)
    except (OSError, StopIteration):  # not Linux
        print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Run the benchmark, print the table; returns the headline figures."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--smoke", action="store_true", help="tiny bags (for the unit test)")
    ap.add_argument("--seconds", type=float, default=2400.0, help="log length of the 1x bag, s")
    ap.add_argument("--no-rss", action="store_true", help="skip the 1x/10x peak RSS check")
    ap.add_argument("--rss-child", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.rss_child:
        _rss_child(args.rss_child)
        return {}
    seconds = 6.0 if args.smoke else args.seconds
    figures: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="bench_readers_") as tmp:
        # Warm up (imports, typestores) on a tiny bag so the timings are of reading only.
        warm = Path(tmp) / "warm.bag"
        make_ros1_bag(warm, 1.0, "lz4")
        for fn in READERS.values():
            fn(warm)
        rows: list[Row] = []
        for bag_name, make in BAG_MAKERS.items():
            path = Path(tmp) / (bag_name.replace(" ", "_") + ".bag")
            t = time.perf_counter()
            count = make(path, seconds)
            print(
                f"# {bag_name}: {count} messages, {path.stat().st_size / 1e6:.1f} MB, "
                f"written in {time.perf_counter() - t:.1f} s",
                flush=True,
            )
            for reader_name, fn in READERS.items():
                n, dt = _time(fn, path)
                rows.append(Row(bag_name, reader_name, n, dt))
                figures[f"messages {bag_name} / {reader_name}"] = n
                figures[f"rate {bag_name} / {reader_name}"] = rows[-1].rate
        print(f"{'bag':<20} {'reader':<32} {'messages':>10} {'s':>8} {'msg/s':>12}")
        for r in rows:
            print(f"{r.bag:<20} {r.reader:<32} {r.messages:>10} {r.seconds:>8.3f} {r.rate:>12.0f}")
        for bag_name in BAG_MAKERS:
            ours = next(
                r for r in rows if r.bag == bag_name and r.reader == "sonarmap RosLogReader"
            )
            ref = next(r for r in rows if r.bag == bag_name and r.reader.startswith("rosbags"))
            ratio = ours.rate / ref.rate
            figures[f"speedup {bag_name}"] = ratio
            print(f"speed-up over rosbags, {bag_name}: {ratio:.1f}x (target >= 10x)")

        if args.no_rss:
            return figures
        small = Path(tmp) / "rss_1x.bag"
        large = Path(tmp) / "rss_10x.bag"
        make_ros1_bag(small, seconds, "lz4")
        make_ros1_bag(large, 10 * seconds, "lz4")
        rss1, rss10 = peak_rss_mb(small), peak_rss_mb(large)
        figures["rss 1x MB"], figures["rss 10x MB"] = rss1, rss10
        figures["rss growth"] = rss10 / rss1
        print(
            f"peak RSS of our reader (lz4): 1x bag {small.stat().st_size / 1e6:.1f} MB -> "
            f"{rss1:.0f} MB, 10x bag {large.stat().st_size / 1e6:.1f} MB -> {rss10:.0f} MB, "
            f"growth {rss10 / rss1:.2f}x (target <= 1.2x)"
        )
    return figures


if __name__ == "__main__":
    main()
