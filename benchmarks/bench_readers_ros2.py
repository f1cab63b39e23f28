"""ROS 2 MCAP reading speed: McapSource + decode_cdr vs rosbags AnyReader + deserialize_cdr.

Writes a ROS 2 MCAP bag with rosbags' Writer (16 Range frames on /sonar + Odometry on
/odom, ~500k messages; ``--smoke``: 5k) into a temp dir, then times both readers over all
messages, decoding Range and Odometry fields. Prints messages/s and the ratio (target ≥ 10).
Usage: ``.venv/bin/python benchmarks/bench_readers_ros2.py [--smoke]``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from formats.ros.decode_cdr import decode_cdr
from formats.ros.mcap_source import McapSource

SENSORS = 16


def write_bag(path: Path, n_scans: int) -> int:
    """A bag of ``n_scans`` × (16 Range + 1 Odometry) messages; returns the message count."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    g = ts.types
    count = 0
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        rng = w.add_connection("/sonar", "sensor_msgs/msg/Range", typestore=ts)
        odo = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        # Serialize one template per sensor, then patch stamp and range bytes: writing
        # 500k messages through the typestore would dominate the benchmark's run time.
        templates = []
        for k in range(SENSORS):
            hdr = g["std_msgs/msg/Header"](
                stamp=g["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                frame_id=f"sonar_{k:02d}_link",
            )
            msg = g["sensor_msgs/msg/Range"](
                header=hdr,
                radiation_type=0,
                field_of_view=0.5,
                min_range=0.02,
                max_range=5.0,
                range=1.0,
                variance=0.01,
            )
            templates.append(bytearray(ts.serialize_cdr(msg, "sensor_msgs/msg/Range")))
        pose = g["geometry_msgs/msg/Pose"](
            position=g["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
            orientation=g["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        vec = g["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        odom = g["nav_msgs/msg/Odometry"](
            header=g["std_msgs/msg/Header"](
                stamp=g["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="odom"
            ),
            child_frame_id="base_link",
            pose=g["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=g["geometry_msgs/msg/TwistWithCovariance"](
                twist=g["geometry_msgs/msg/Twist"](linear=vec, angular=vec),
                covariance=np.zeros(36),
            ),
        )
        odom_t = bytearray(ts.serialize_cdr(odom, "nav_msgs/msg/Odometry"))
        rng_at = len(templates[0]) - 8  # range, variance are the last two float32
        for i in range(n_scans):
            t = 1_700_000_000_000_000_000 + i * 50_000_000
            for k in range(SENSORS):
                data = templates[k]
                data[4:12] = np.array([t // 10**9, t % 10**9], "<u4").tobytes()
                data[rng_at : rng_at + 4] = np.float32(0.5 + (i + k) % 40 * 0.1).tobytes()
                w.write(rng, t + k * 1000, bytes(data))
            odom_t[4:12] = np.array([t // 10**9, t % 10**9], "<u4").tobytes()
            w.write(odo, t + 20_000, bytes(odom_t))
            count += SENSORS + 1
    return count


def ours(bag: Path) -> tuple[int, float]:
    """Messages and sum of ranges + x via McapSource + decode_cdr."""
    n, total = 0, 0.0
    with McapSource(next(bag.glob("*.mcap"))) as src:
        for raw in src.raw_batches([c.id for c in src.connections]):
            cols: Any = decode_cdr(raw)
            n += len(raw)
            total += float(cols.range.sum()) if hasattr(cols, "range") else float(cols.x.sum())
    return n, total


def rosbags_reader(bag: Path) -> tuple[int, float]:
    """The same through rosbags' AnyReader + deserialize_cdr, one message at a time."""
    n, total = 0, 0.0
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, _, data in reader.messages():
            msg: Any = reader.deserialize(data, conn.msgtype)
            n += 1
            total += float(msg.range) if conn.topic == "/sonar" else msg.pose.pose.position.x
    return n, total


def bench_mcap_ros2(smoke: bool = False) -> dict[str, float]:
    """Print messages/s of both readers and their ratio; returns them."""
    n_scans = 300 if smoke else 29_412  # × 17 messages ≈ 5k / 500k
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bag"
        t0 = time.perf_counter()
        count = write_bag(bag, n_scans)
        size = sum(p.stat().st_size for p in bag.iterdir())
        print(f"wrote {count} messages ({size / 1e6:.1f} MB) in {time.perf_counter() - t0:.1f} s")
        rows = []
        for name, fn in (("McapSource+decode_cdr", ours), ("rosbags AnyReader", rosbags_reader)):
            t0 = time.perf_counter()
            n, total = fn(bag)
            dt = time.perf_counter() - t0
            assert n == count, (name, n, count)
            rows.append((name, n / dt, total))
            print(f"{name:24s} {n:8d} msgs {dt:7.2f} s {n / dt:12,.0f} msg/s  checksum {total:.3f}")
        assert abs(rows[0][2] - rows[1][2]) < 1e-3 * max(1.0, abs(rows[1][2])), "checksums differ"
        print(f"ratio: {rows[0][1] / rows[1][1]:.1f}x (target >= 10x)")
    return {"messages": float(count), "sonarmap": rows[0][1], "rosbags": rows[1][1],
            "speedup": rows[0][1] / rows[1][1]}


if __name__ == "__main__":
    bench_mcap_ros2(smoke="--smoke" in sys.argv)
