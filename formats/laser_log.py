"""Laser logs, read for ``sonarmap emulate``: CARMEN ``FLASER`` logs and
``sensor_msgs/LaserScan`` in ROS 1 / ROS 2 bags and MCAP files.

A CARMEN log gives each scan with its (SLAM-corrected) pose: :func:`read_carmen_laser_log`
returns a :class:`LaserLog`. A ROS log gives the scans and the robot's pose stream
separately (:func:`read_ros_laser_scans`, through the ROS reader's topic selection and tf);
the pipeline interpolates the poses at the scan stamps.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from formats.contract import PoseBatch, SensorMount
from formats.errors import InputError

if TYPE_CHECKING:
    from formats.carmen import CarmenOdom
    from formats.ros.columns import LaserScanColumns
    from formats.ros.reader import RosLogReader


@dataclass(frozen=True)
class LaserLog:
    """Laser scans with the robot pose at each scan, ``S`` scans of up to ``B`` beams.

    ``ranges``/``angles`` are (S, B), NaN-padded where a scan has fewer beams; angles in
    the laser frame (rad). ``x, y, yaw``: base pose in ``parent_frame`` per scan (m, rad).
    """

    t_ns: I64
    ranges: F64
    angles: F64
    range_min: F64  # (S,) m
    range_max: F64  # (S,) m: readings >= this are no return
    x: F64
    y: F64
    yaw: F64
    laser_mount: SensorMount  # laser in the base frame
    parent_frame: str
    child_frame: str
    source_format: str
    notes: tuple[str, ...] = ()
    # The robot's own wheel odometry (frame ``odom``), when the log has it apart from the
    # scan poses (CARMEN ODOM lines): real drift for ``emulate --raw-odometry``.
    odometry: PoseBatch | None = None

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def take(self, index: npt.NDArray[np.intp]) -> LaserLog:
        """The scans at ``index``, in that order (everything else kept)."""
        return dataclasses.replace(
            self, t_ns=self.t_ns[index], ranges=self.ranges[index], angles=self.angles[index],
            range_min=self.range_min[index], range_max=self.range_max[index],
            x=self.x[index], y=self.y[index], yaw=self.yaw[index],
        )

    def laser_poses(self) -> tuple[F64, F64, F64]:
        """World (parent-frame) pose of the laser per scan: base pose ∘ laser mount."""
        m = self.laser_mount
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return (
            self.x + c * m.x - s * m.y,
            self.y + s * m.x + c * m.y,
            wrap_angle(self.yaw + m.yaw),
        )

    def valid_returns(self) -> npt.NDArray[np.bool_]:
        """(S, B): beams that are echoes (finite, within [range_min, range_max))."""
        r = self.ranges
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r >= self.range_min[:, None]) & (r < self.range_max[:, None])


# Scan period given to a CARMEN log whose stamps do not order its scans (it has no time), ns;
# its scans are stamped from 0 s (its first stamp may be anything: −0.45 s, 4.29497e+09 s).
UNSTAMPED_SCAN_PERIOD_NS = 1_000_000_000


def stamps_order_scans(t_ns: I64) -> bool:
    """Whether a log's scan stamps carry its time: at least half of consecutive stamps
    increase. Some Radish logs carry none — every stamp equal (Örebro, Freiburg campus) or
    written to six significant digits, ``1.13486e+09`` (MIT CSAIL, Belgioioso, the Infinite
    Corridor): 99-100 % of consecutive scans share a stamp, where the logs with time
    have 0-1 % not increasing (the Intel lab 4 of 910)."""
    if t_ns.shape[0] < 2:
        return True
    return bool(int(np.count_nonzero(np.diff(t_ns) > 0)) * 2 >= t_ns.shape[0] - 1)


def sorted_by_time(log: LaserLog) -> LaserLog:
    """The scans in stamp order (stable), with a note when they were not."""
    order = np.argsort(log.t_ns, kind="stable")
    if np.all(order == np.arange(len(log))):
        return log
    moved = int(np.count_nonzero(np.diff(log.t_ns) < 0))
    note = f"{moved} scans had stamps going backwards; scans sorted by stamp"
    return dataclasses.replace(log.take(order), notes=(*log.notes, note))


def read_carmen_laser_log(
    p: Path, base_frame: str, max_scans: int | None, laser_max_range: float | None
) -> LaserLog:
    """A CARMEN log's FLASER scans with the robot (base) pose of each: the logged,
    SLAM-corrected laser pose moved to the base by the laser offset, frame ``map``."""
    from formats.carmen import read_carmen

    log = read_carmen(p, max_scans=max_scans, laser_max_range=laser_max_range)
    las = log.laser
    if len(las) == 0:
        raise InputError("the CARMEN log has no FLASER laser scans", p)
    m = log.laser_mount
    # FLASER x y theta is the laser's pose: the base is the laser pose ∘ mount⁻¹.
    yaw = wrap_angle(las.yaw - m.yaw)
    c, s = np.cos(yaw), np.sin(yaw)
    x = las.x - (c * m.x - s * m.y)
    y = las.y - (s * m.x + c * m.y)
    s_n, b_n = las.ranges.shape
    notes = [
        f"CARMEN log: {s_n} FLASER scans of {b_n} beams over {math.degrees(las.fov_rad):.0f}°, "
        f"laser max {las.max_range:g} m, laser offset {m.x:g} m; poses = the logged "
        "(corrected) FLASER poses, frame map"
    ]
    if log.skipped:
        skipped = ", ".join(f"{k} {v}" for k, v in sorted(log.skipped.items()))
        notes.append(f"CARMEN lines not used: {skipped}")
    odometry = carmen_odometry(log.odom, base_frame)
    t_ns = las.t_ns
    if not stamps_order_scans(t_ns):
        # The log carries no time (stamps_order_scans). The scans are in log order;
        # stamping them a fixed period apart keeps that order.
        same = int(np.count_nonzero(np.diff(t_ns) <= 0))
        t_ns = np.arange(s_n, dtype=np.int64) * UNSTAMPED_SCAN_PERIOD_NS
        notes.append(
            f"{same} of {s_n - 1} FLASER stamps do not increase (the log carries no time): "
            f"scans stamped {UNSTAMPED_SCAN_PERIOD_NS / 1e9:g} s apart from 0 s in log order"
        )
        odometry = None  # no common clock: ODOM lines cannot be matched to the scans
    if odometry is not None:
        notes.append(f"raw odometry: {len(odometry)} ODOM poses (emulate --raw-odometry logs them)")
    return LaserLog(
        t_ns=t_ns,
        ranges=las.ranges,
        angles=np.broadcast_to(las.angles, las.ranges.shape).copy(),
        range_min=np.zeros(s_n),
        range_max=np.full(s_n, las.max_range),
        x=x,
        y=y,
        yaw=yaw,
        laser_mount=m,
        parent_frame="map",
        child_frame=base_frame,
        source_format="carmen",
        notes=tuple(notes),
        odometry=odometry,
    )


def carmen_odometry(odom: CarmenOdom, base_frame: str) -> PoseBatch | None:
    """A CARMEN log's ODOM lines as the robot's raw odometry (``odom → base_frame``), in
    stamp order, one pose per stamp (the first); None without two distinct stamps (the
    Örebro log's lines carry no time)."""
    if len(odom) < 2 or np.all(odom.t_ns == odom.t_ns[0]):
        return None
    order = np.argsort(odom.t_ns, kind="stable")
    t = odom.t_ns[order]
    first = np.concatenate([[True], np.diff(t) > 0])
    idx = order[first]
    return PoseBatch(
        t[first], odom.x[idx], odom.y[idx], wrap_angle(odom.yaw[idx]), "odom", base_frame
    )


@dataclass(frozen=True)
class LaserScans:
    """LaserScan messages of one topic as a table of ``S`` scans of up to ``B`` beams, the
    laser's mount (from ``/tf_static``, else the base origin) and the log's pose stream."""

    topic: str
    t_ns: I64
    ranges: F64  # (S, B), NaN-padded
    angles: F64  # (S, B), laser frame, rad
    range_min: F64
    range_max: F64
    laser_mount: SensorMount
    poses: list[PoseBatch]  # one parent → child pair (the first the log has)
    notes: tuple[str, ...]


def read_ros_laser_scans(
    reader: RosLogReader, max_scans: int | None, laser_topic: str | None
) -> LaserScans:
    """The LaserScan topic of a ROS log (``laser_topic``, else the only one), its laser
    mount and the robot poses, through the reader's topic selection and tf."""
    topic = reader.laser_topic(laser_topic)
    parts = reader.laser_columns(topic, max_scans)
    if not parts:
        raise InputError(f"laser topic {topic} has no messages", reader.path)
    poses = [b for b in reader.batches(["poses"]) if isinstance(b, PoseBatch)]
    pairs = {(b.parent_frame, b.child_frame) for b in poses}
    if len(pairs) > 1:
        first = (poses[0].parent_frame, poses[0].child_frame)
        poses = [b for b in poses if (b.parent_frame, b.child_frame) == first]
    t, ranges, angles, rmin, rmax, frame = _laser_table(parts, max_scans)
    base = reader.config.input.base_frame
    notes = [f"{topic}: {len(t)} LaserScan messages of up to {ranges.shape[1]} beams"]
    mount = reader.static_mount(frame) if frame else None
    if mount is None:
        mount = SensorMount(0.0, 0.0, 0.0)
        notes.append(
            f"no static transform {base} → {frame or '(empty frame)'}: laser at the base origin"
        )
    else:
        notes.append(f"laser {frame} at ({mount.x:.3f}, {mount.y:.3f}) m, yaw {mount.yaw:.3f} rad")
    return LaserScans(topic, t, ranges, angles, rmin, rmax, mount, poses, tuple(notes))


def _laser_table(
    cols: Sequence[LaserScanColumns], max_scans: int | None
) -> tuple[I64, F64, F64, F64, F64, str]:
    """LaserScan columns → (t, ranges (S,B), angles (S,B), rmin, rmax, laser frame)."""
    t = np.concatenate([c.stamp_ns for c in cols]).astype(np.int64)
    a0 = np.concatenate([c.angle_min for c in cols])
    da = np.concatenate([c.angle_increment for c in cols])
    rmin = np.concatenate([c.range_min for c in cols])
    rmax = np.concatenate([c.range_max for c in cols])
    per = np.concatenate([c.beams_per_message for c in cols]).astype(np.int64)
    flat = np.concatenate([c.ranges for c in cols])
    frame = cols[0].frames[int(cols[0].frame[0])] if len(cols[0].frame) else ""
    n = t.shape[0] if max_scans is None else min(max_scans, t.shape[0])
    flat = flat[: int(per[:n].sum())]
    t, a0, da, rmin, rmax, per = t[:n], a0[:n], da[:n], rmin[:n], rmax[:n], per[:n]
    width = max(int(per.max()), 1)
    row = np.repeat(np.arange(n), per)
    starts = np.concatenate([[0], np.cumsum(per)[:-1]])
    col = np.arange(flat.shape[0]) - np.repeat(starts, per)
    ranges = np.full((n, width), np.nan)
    ranges[row, col] = flat
    angles = np.full((n, width), np.nan)
    angles[row, col] = a0[row] + col * da[row]
    return t, ranges, angles, rmin, rmax, frame
