"""The echoes pose refinement works on: every valid sonar echo as a point in the robot
frame at its own stamp, with the odometry pose it was taken at.

A reading is an echo when its range is finite, at least the sensor's ``r_min`` and below
``r_max − ε_max`` (ALGORITHM.md §1), and not longer than ``max_echo_range_m`` (a wide
beam's lateral uncertainty grows with range, so far echoes blur matching more than they
help). An echo says an obstacle lies somewhere on the arc of radius ``d`` across the beam
(§1 places the feature on its axis; matching uses the whole arc), so each echo is kept as
``ARC_SAMPLES`` points spread evenly over ``±arc_fraction·β/2`` around the axis, in the
base frame through the sensor's mount, so they can be moved with any pose estimate later.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from formats.arrays import F64, I64
from pipeline.stages.pose_sync import POSE_OK, PoseTrack, interpolate_poses
from pipeline.stages.sensors import SensorTable
from pipeline.streaming.reorder_window import RangeChunk

ARC_SAMPLES = 7
ARC_FRACTION = 0.8  # an echo is placed along ± this fraction of its half beam (sharpness, matching)


@dataclass(frozen=True)
class Echoes:
    """Echoes in time order: stamp (ns), arc points in the base frame (m), odometry pose."""

    t_ns: I64
    bx: F64  # (N, ARC_SAMPLES)
    by: F64
    odo: F64  # (N, 3) odometry pose (x, y, yaw) of the robot at t_ns
    sx: F64  # (N,) the sensor's position in the base frame, m (the apex of the echo's cone)
    sy: F64
    axis: F64  # (N,) the beam axis in the base frame, rad
    half: F64  # (N,) half the beam width, rad
    range_m: F64  # (N,) the echo's range, m

    def arc_angles(self, fraction: float, samples: int = ARC_SAMPLES) -> F64:
        """(N, ``samples``) directions of each echo's arc points over ``±fraction`` of its
        half beam, in the base frame (rad)."""
        u = np.linspace(-1.0, 1.0, samples) * fraction
        return np.asarray(self.axis[:, None] + self.half[:, None] * u[None, :])

    def arc(self, fraction: float, samples: int = ARC_SAMPLES) -> tuple[F64, F64]:
        """``samples`` points of each echo's arc over ``±fraction`` of its half beam, in
        the base frame."""
        ang = self.arc_angles(fraction, samples)
        return (self.sx[:, None] + self.range_m[:, None] * np.cos(ang),
                self.sy[:, None] + self.range_m[:, None] * np.sin(ang))

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def mounts(self) -> I64:
        """Per echo, the number of its sensor's mount (position and axis in the base frame):
        the echoes of one sonar share it."""
        key = np.column_stack([self.sx, self.sy, self.axis])
        return np.unique(key, axis=0, return_inverse=True)[1].ravel().astype(np.int64)

    def on_track(self, t_ns: I64, x: F64, y: F64, yaw: F64) -> Echoes:
        """These echoes with their odometry read again from the pose track ``(x, y, yaw)``
        at ``t_ns`` (interpolated at each echo's stamp)."""
        look = interpolate_poses(PoseTrack(t_ns, x, y, yaw, "", ""), self.t_ns,
                                 np.iinfo(np.int64).max)
        return dataclasses.replace(self, odo=np.column_stack([look.x, look.y, look.yaw]))

    def within(self, range_m: float) -> Echoes:
        """The echoes no farther than ``range_m`` (in their order)."""
        return self.take(np.flatnonzero(self.range_m <= range_m))

    def take(self, index: I64) -> Echoes:
        """The echoes at ``index`` (in that order)."""
        return Echoes(*(getattr(self, f.name)[index] for f in dataclasses.fields(self)))


def collect_echoes(
    chunks: Iterable[RangeChunk],
    track: PoseTrack,
    sensors: SensorTable,
    *,
    eps_max: float,
    max_echo_range_m: float,
    arc_fraction: float = ARC_FRACTION,
    time_offset_ns: int,
    max_gap_ns: int,
) -> Echoes:
    """One pass over the log's readings in time order (``chunks``: the survey's spill,
    :meth:`pipeline.stages.ingest.Survey.ordered_ranges`, so the log is not decoded again)
    keeping the echoes that have a pose."""
    parts: list[tuple[I64, F64, F64, F64, F64, F64, F64]] = []
    for chunk in chunks:
        b = chunk.batch
        if len(b) == 0:
            continue
        fov, lo, hi = sensors.apply_limits(b)
        r = b.range_m
        with np.errstate(invalid="ignore"):
            echo = np.isfinite(r) & (r >= lo) & (r < hi - eps_max) & (r <= max_echo_range_m)
        sid = b.sensor_id
        echo &= np.isfinite(sensors.mount_x[sid])
        if not echo.any():
            continue
        t = b.t_ns[echo]
        look = interpolate_poses(track, t + time_offset_ns, max_gap_ns)
        ok = look.reason == POSE_OK
        sid = sid[echo][ok]
        rr = r[echo][ok]
        odo = np.column_stack([look.x[ok], look.y[ok], look.yaw[ok]])
        parts.append((t[ok], odo, sensors.mount_x[sid], sensors.mount_y[sid],
                      sensors.mount_yaw[sid], 0.5 * fov[echo][ok], rr))
    if parts:
        cols = [np.concatenate([p[k] for p in parts]) for k in range(7)]
    else:
        cols = [np.empty(0, np.int64), np.empty((0, 3)), *(np.empty(0) for _ in range(5))]
    empty = np.empty((0, ARC_SAMPLES))
    echoes = Echoes(cols[0], empty, empty, *cols[1:])
    bx, by = echoes.arc(arc_fraction)
    return dataclasses.replace(echoes, bx=bx, by=by)
