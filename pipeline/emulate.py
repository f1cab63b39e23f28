"""Emulate a sonar ring from real laser scans (``sonarmap emulate``).

Each virtual sonar of a ring reads, per laser scan, the **shortest laser return inside its
cone**: laser endpoints are put in the robot base frame, and those whose bearing from the
sonar's origin is within ±β/2 of its axis give the reading (their minimum distance from
the sonar). No return inside the cone closer than the sonar's maximum range reads the
maximum range (the mapper's "no echo"); a return closer than the sonar's minimum range
reads −inf (REP 117, too close). Laser readings at or above the laser's maximum, below its
minimum, or not finite are not echoes.

Only sonars the laser can see for are emitted: a sonar whose beam axis, followed to its
maximum range, lies outside the laser's field of view is dropped (with a Pioneer ring and a
180° front laser: the 8 front sonars). The two side sonars (±90°) then have part of their
cone outside the laser's view, so their readings can be too long there; the emulation
notes say how much. ``require_full_cone`` keeps only sonars whose whole cone is seen.

Inputs: CARMEN logs (``FLASER``, :mod:`formats.carmen`; the robot poses are the logged,
SLAM-corrected laser poses moved to the base by the laser offset, frame ``map``) and
``sensor_msgs/LaserScan`` in ROS 1 / ROS 2 bags and MCAP files (poses from the log's
Odometry or tf through the ROS reader, interpolated at the scan stamps; the laser mount
from ``/tf_static``, else the base origin). Scans are sorted by stamp.

Outputs (:func:`write_emulation`): the sonar log in any format of
:mod:`formats.log_writers` (one Range per emitted sonar per scan, at the scan's stamp;
Odometry from the scan poses; ``/tf_static`` mounts), the **laser occupancy map** as the
reference ``<stem>.laser.yaml/.pgm`` (log-odds of every laser beam ray-cast from the laser
pose, nav2 trinary) and the trajectory ``<stem>.truth.csv`` (``t,x,y,yaw``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F32, F64, I32, I64
from formats.contract import PoseBatch, SensorMount, make_range_batch
from formats.errors import ConfigError, FormatError, InputError, OutputError, TopicError
from formats.log_writers import (
    LogContent,
    reference_paths,
    write_log_with_reference,
)
from formats.map_types import GridSpec
from formats.options import MountConfig
from formats.presets import PRESETS
from pipeline.config import Config

if TYPE_CHECKING:
    from formats.ros.source import MessageSource


DEFAULT_FOV_DEG = 30.0  # Polaroid 600-series beam, full width
DEFAULT_MAX_RANGE_M = 5.0
_COVERAGE_RAYS = 61  # directions sampled across a cone to measure how much the laser sees
_CHUNK_CELLS = 2_000_000  # bound on (scan × beam × sonar) and ray samples held at once


# --------------------------------------------------------------------------- inputs


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

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

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


def _sorted_by_time(log: LaserLog) -> LaserLog:
    order = np.argsort(log.t_ns, kind="stable")
    if np.all(order == np.arange(len(log))):
        return log
    moved = int(np.count_nonzero(np.diff(log.t_ns) < 0))
    note = f"{moved} scans had stamps going backwards; scans sorted by stamp"
    return LaserLog(
        log.t_ns[order],
        log.ranges[order],
        log.angles[order],
        log.range_min[order],
        log.range_max[order],
        log.x[order],
        log.y[order],
        log.yaw[order],
        log.laser_mount,
        log.parent_frame,
        log.child_frame,
        log.source_format,
        (*log.notes, note),
    )


def load_laser_log(
    path: str | Path,
    config: Config | None = None,
    *,
    max_scans: int | None = None,
    laser_topic: str | None = None,
    laser_max_range: float | None = None,
) -> LaserLog:
    """Read laser scans and poses from a CARMEN log or a ROS 1/ROS 2/MCAP LaserScan log.

    The format is detected from the content. ``max_scans`` keeps the first scans (in log
    order); ``laser_topic`` chooses a LaserScan topic when there are several;
    ``laser_max_range`` (m) overrides a CARMEN log's laser maximum.
    """
    from formats import detect_format
    from formats.carmen import looks_like_carmen
    from formats.magic import ROS1_MAGIC

    cfg = config if config is not None else Config()
    p = Path(path)
    if max_scans is not None and max_scans < 1:
        raise ConfigError(f"max_scans must be >= 1, got {max_scans}")
    if not p.exists():
        raise FormatError("no such file or directory", p)
    if p.is_file():
        with p.open("rb") as f:
            head = f.read(16)
        if not head.startswith(ROS1_MAGIC) and looks_like_carmen(p):
            return _sorted_by_time(_load_carmen(p, cfg, max_scans, laser_max_range))
    try:
        fmt = cfg.input.format or detect_format(p)
    except FormatError as err:
        raise FormatError(
            "neither a CARMEN log (FLASER/ODOM/PARAM lines) nor a ROS 1/ROS 2/MCAP log", p
        ) from err
    if fmt not in ("ros1", "ros2", "mcap"):
        raise FormatError(
            f"a {fmt} log has no laser scans; emulate reads CARMEN logs and ROS 1/ROS 2/MCAP "
            "logs with sensor_msgs/LaserScan",
            p,
        )
    return _sorted_by_time(_load_ros(p, fmt, cfg, max_scans, laser_topic))


def _load_carmen(
    p: Path, cfg: Config, max_scans: int | None, laser_max_range: float | None
) -> LaserLog:
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
    return LaserLog(
        t_ns=las.t_ns,
        ranges=las.ranges,
        angles=np.broadcast_to(las.angles, las.ranges.shape).copy(),
        range_min=np.zeros(s_n),
        range_max=np.full(s_n, las.max_range),
        x=x,
        y=y,
        yaw=yaw,
        laser_mount=m,
        parent_frame="map",
        child_frame=cfg.input.base_frame,
        source_format="carmen",
        notes=tuple(notes),
    )


def _ros_source(p: Path, fmt: str) -> MessageSource:
    if fmt == "ros1":
        from formats.ros.ros1bag import Ros1BagSource

        return Ros1BagSource(p)
    if fmt == "ros2":
        from formats.ros.ros2bag import Ros2BagSource

        return Ros2BagSource(p)
    from formats.ros.mcap_source import McapSource

    return McapSource(p)


def _load_ros(
    p: Path, fmt: str, cfg: Config, max_scans: int | None, laser_topic: str | None
) -> LaserLog:
    from formats.ros import tf as tflib
    from formats.ros.columns import LASER_TYPES, TF_TYPES, LaserScanColumns, TransformColumns
    from formats.ros.decode import decode
    from formats.ros.reader import RosLogReader
    from pipeline.pose_sync import POSE_OK, build_pose_track, interpolate_poses

    source = _ros_source(p, fmt)
    with RosLogReader(source, cfg) as reader:
        conns = source.connections
        lasers = sorted({c.topic for c in conns if c.msgtype in LASER_TYPES})
        listing = ", ".join(sorted({f"{c.topic}:{c.msgtype}" for c in conns})) or "nothing"
        if laser_topic:
            if laser_topic not in lasers:
                raise TopicError(
                    f"laser topic {laser_topic} is not a sensor_msgs/LaserScan topic of the "
                    f"log; the log contains: {listing}",
                    p,
                )
            topic = laser_topic
        elif len(lasers) == 1:
            topic = lasers[0]
        elif not lasers:
            raise TopicError(f"no sensor_msgs/LaserScan topic; the log contains: {listing}", p)
        else:
            raise TopicError(
                f"several LaserScan topics ({', '.join(lasers)}): choose one with --laser-topic",
                p,
            )

        parts: list[LaserScanColumns] = []
        count = 0
        gen = source.raw_batches([c.id for c in conns if c.topic == topic])
        try:
            for raw in gen:
                cols = decode(raw)
                assert isinstance(cols, LaserScanColumns)
                parts.append(cols)
                count += cols.stamp_ns.shape[0]
                if max_scans is not None and count >= max_scans:
                    break
        except FormatError as err:
            if err.path is None:
                raise FormatError(err.reason, p) from err
            raise
        finally:
            close = getattr(gen, "close", None)
            if close is not None:
                close()
        if count == 0:
            raise InputError(f"laser topic {topic} has no messages", p)

        poses = [b for b in reader.batches(["poses"]) if isinstance(b, PoseBatch)]
        pairs = {(b.parent_frame, b.child_frame) for b in poses}
        if len(pairs) > 1:
            first = (poses[0].parent_frame, poses[0].child_frame)
            poses = [b for b in poses if (b.parent_frame, b.child_frame) == first]
        track = build_pose_track(poses)

        tables: list[tuple[TransformColumns, bool]] = []
        tf_ids = [c.id for c in conns if c.msgtype in TF_TYPES]
        if tf_ids:
            for raw in source.raw_batches(tf_ids):
                tcols = decode(raw)
                if isinstance(tcols, TransformColumns):
                    tables.append((tcols, raw.connection.topic.rstrip("/").endswith("tf_static")))
        links = tflib.build_links(tables)

    t, ranges, angles, rmin, rmax, frame = _laser_table(parts, max_scans)
    base = cfg.input.base_frame
    notes = [f"{topic}: {len(t)} LaserScan messages of up to {ranges.shape[1]} beams"]
    mount = tflib.static_mount(links, base, frame.lstrip("/")) if frame else None
    if mount is None:
        mount = SensorMount(0.0, 0.0, 0.0)
        notes.append(
            f"no static transform {base} → {frame or '(empty frame)'}: laser at the base origin"
        )
    else:
        notes.append(f"laser {frame} at ({mount.x:.3f}, {mount.y:.3f}) m, yaw {mount.yaw:.3f} rad")
    look = interpolate_poses(track, t, round(cfg.pose_sync.max_pose_gap_s * 1e9))
    ok = look.reason == POSE_OK
    if not ok.any():
        raise InputError(f"no robot pose at any of the {len(t)} laser scan stamps", p)
    if not ok.all():
        notes.append(
            f"{int((~ok).sum())} scans without a robot pose (outside the poses or in a gap) dropped"
        )
    notes.append(
        f"poses {track.parent_frame} → {track.child_frame} interpolated at the scan stamps"
    )
    return LaserLog(
        t_ns=t[ok],
        ranges=ranges[ok],
        angles=angles[ok],
        range_min=rmin[ok],
        range_max=rmax[ok],
        x=look.x[ok],
        y=look.y[ok],
        yaw=look.yaw[ok],
        laser_mount=mount,
        parent_frame=track.parent_frame,
        child_frame=track.child_frame or base,
        source_format=fmt,
        notes=tuple(notes),
    )


def _laser_table(
    parts: Sequence[object], max_scans: int | None
) -> tuple[I64, F64, F64, F64, F64, str]:
    """LaserScan columns → (t, ranges (S,B), angles (S,B), rmin, rmax, laser frame)."""
    from formats.ros.columns import LaserScanColumns

    cols = [c for c in parts if isinstance(c, LaserScanColumns)]
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


# --------------------------------------------------------------------------- the ring


@dataclass(frozen=True)
class VirtualRing:
    """Sonars to emulate, in the base frame: one entry per sonar (m, rad)."""

    names: tuple[str, ...]
    x: F64
    y: F64
    yaw: F64
    fov: F64  # full beam width β
    min_range: F64
    max_range: F64

    def __len__(self) -> int:
        return len(self.names)

    def take(self, index: npt.NDArray[np.intp]) -> VirtualRing:
        return VirtualRing(
            tuple(self.names[i] for i in index.tolist()),
            self.x[index],
            self.y[index],
            self.yaw[index],
            self.fov[index],
            self.min_range[index],
            self.max_range[index],
        )


def ring_from_mounts(
    mounts: Sequence[MountConfig],
    *,
    fov_deg: float | None = None,
    max_range: float | None = None,
    default_fov_deg: float = DEFAULT_FOV_DEG,
    default_min_range: float = 0.0,
    default_max_range: float = DEFAULT_MAX_RANGE_M,
) -> VirtualRing:
    """The ring of ``mounts``; ``fov_deg``/``max_range`` override every sonar, mount values
    of 0 ("from the log") take the defaults."""
    if not mounts:
        raise ConfigError("no sonar mounts to emulate (give a preset or [[sensors.mounts]])")
    if fov_deg is not None and not 0 < fov_deg < 180:
        raise ConfigError(f"fov_deg must be in (0, 180), got {fov_deg!r}")
    if max_range is not None and not (max_range > 0 and math.isfinite(max_range)):
        raise ConfigError(f"max_range must be > 0, got {max_range!r}")
    fov = [fov_deg if fov_deg is not None else (m.fov_deg or default_fov_deg) for m in mounts]
    rmax = [
        max_range if max_range is not None else (m.max_range or default_max_range) for m in mounts
    ]
    rmin = [m.min_range or default_min_range for m in mounts]
    for m, lo, hi in zip(mounts, rmin, rmax, strict=True):
        if not lo < hi:
            raise ConfigError(f"sonar {m.name}: min range {lo} m is not below max range {hi} m")
    return VirtualRing(
        names=tuple(m.name for m in mounts),
        x=np.array([m.x for m in mounts], np.float64),
        y=np.array([m.y for m in mounts], np.float64),
        yaw=np.radians(np.array([m.yaw_deg for m in mounts], np.float64)),
        fov=np.radians(np.array(fov, np.float64)),
        min_range=np.array(rmin, np.float64),
        max_range=np.array(rmax, np.float64),
    )


def mounts_from_config(cfg: Config, preset: str | None = None) -> tuple[MountConfig, ...]:
    """Sonar mounts: ``preset`` if given, else ``[[sensors.mounts]]``, else the config's
    preset, else the Pioneer P3-DX ring."""
    if preset:
        if preset not in PRESETS:
            raise ConfigError(f"unknown preset '{preset}' (known: {', '.join(sorted(PRESETS))})")
        return PRESETS[preset]
    sc = cfg.sensors
    if sc.mounts:
        return sc.mounts
    return PRESETS[sc.preset or "pioneer-p3dx"]


def laser_view(log: LaserLog) -> tuple[float, float]:
    """The laser's field of view in its frame, ``(lo, hi)`` rad, half a beam either side."""
    a = log.angles
    finite = a[np.isfinite(a)]
    if finite.size == 0:
        raise InputError("laser scans have no beams")
    steps = np.diff(a, axis=1)
    steps = np.abs(steps[np.isfinite(steps) & (steps != 0)])
    half = 0.5 * float(np.median(steps)) if steps.size else 0.0
    return float(finite.min()) - half, float(finite.max()) + half


def cone_coverage(
    ring: VirtualRing, mount: SensorMount, view: tuple[float, float]
) -> tuple[F64, npt.NDArray[np.bool_]]:
    """Per sonar: the fraction of its cone (sampled at its max range) inside the laser's
    view, and whether its axis (at max range) is inside."""
    lo, hi = view
    u = np.linspace(-0.5, 0.5, _COVERAGE_RAYS)
    # (K, R+1): R rays across the cone, then the axis.
    ang = ring.yaw[:, None] + np.concatenate(
        [u[None, :] * ring.fov[:, None], np.zeros((len(ring), 1))], axis=1
    )
    px = ring.x[:, None] + ring.max_range[:, None] * np.cos(ang) - mount.x
    py = ring.y[:, None] + ring.max_range[:, None] * np.sin(ang) - mount.y
    bearing = np.arctan2(py, px) - mount.yaw
    if hi - lo >= 2 * np.pi:
        inside = np.ones(bearing.shape, bool)
    else:
        inside = (bearing - lo) % (2 * np.pi) <= hi - lo
    return inside[:, :-1].mean(axis=1), inside[:, -1]


# --------------------------------------------------------------------------- emulation


def emulate_ranges(log: LaserLog, ring: VirtualRing) -> F64:
    """(S, K) sonar readings (m): per scan and sonar, the shortest laser return inside the
    cone; max range when none is closer; −inf when closer than the min range."""
    s_n, b_n = log.ranges.shape
    k_n = len(ring)
    m = log.laser_mount
    valid = log.valid_returns()
    r = np.where(valid, log.ranges, 0.0)
    th = np.where(valid, log.angles, 0.0) + m.yaw
    ex = m.x + r * np.cos(th)  # endpoints in the base frame
    ey = m.y + r * np.sin(th)
    half = 0.5 * ring.fov
    out = np.empty((s_n, k_n))
    step = max(1, _CHUNK_CELLS // max(b_n * k_n, 1))
    for a in range(0, s_n, step):
        sl = slice(a, min(a + step, s_n))
        dx = ex[sl, :, None] - ring.x
        dy = ey[sl, :, None] - ring.y
        bearing = wrap_angle(np.arctan2(dy, dx) - ring.yaw)
        inside = valid[sl, :, None] & (np.abs(bearing) <= half)
        out[sl] = np.where(inside, np.hypot(dx, dy), np.inf).min(axis=1)
    reading = np.where(out < ring.max_range, out, ring.max_range)
    return np.where(out < ring.min_range, -np.inf, reading)


@dataclass(frozen=True)
class Emulation:
    """An emulated sonar log: the content to write, the per-scan readings and notes."""

    content: LogContent
    ranges: F64  # (S, K) readings of the emitted sonars
    ring: VirtualRing  # the emitted sonars
    dropped: tuple[str, ...]  # sonars not emitted (outside the laser's view)
    notes: tuple[str, ...]


def emulate(log: LaserLog, ring: VirtualRing, *, require_full_cone: bool = False) -> Emulation:
    """Emulate the ring's sonars the laser can see for over every scan of ``log``."""
    if len(log) == 0:
        raise InputError("no laser scans to emulate from")
    view = laser_view(log)
    coverage, axis_in = cone_coverage(ring, log.laser_mount, view)
    keep = coverage >= 1.0 if require_full_cone else axis_in
    idx = np.nonzero(keep)[0]
    dropped = tuple(ring.names[i] for i in np.nonzero(~keep)[0].tolist())
    notes = list(log.notes)
    rule = "whole cone" if require_full_cone else "beam axis"
    notes.append(
        f"laser view {math.degrees(view[0]):.1f}…{math.degrees(view[1]):.1f}°; "
        f"emitted {len(idx)} of {len(ring)} sonars ({rule} inside the laser's view)"
        + (f"; not emitted: {', '.join(dropped)}" if dropped else "")
    )
    partial = [
        f"{ring.names[i]} {100 * (1 - coverage[i]):.0f}%" for i in idx.tolist() if coverage[i] < 1.0
    ]
    if partial:
        notes.append(
            "cone outside the laser's view (readings there may be too long): " + ", ".join(partial)
        )
    if idx.size == 0:
        raise InputError("no sonar of the ring lies inside the laser's field of view; " + notes[-1])
    sub = ring.take(idx)
    ranges = emulate_ranges(log, sub)
    s_n, k_n = ranges.shape
    t = np.repeat(log.t_ns, k_n)
    sid = np.tile(np.arange(k_n, dtype=np.int32), s_n)
    batch = make_range_batch(
        t,
        sid,
        ranges.reshape(-1),
        sub.fov[sid],
        sub.min_range[sid],
        sub.max_range[sid],
        scan_id=np.repeat(np.arange(s_n, dtype=np.int64), k_n),
    )
    poses = PoseBatch(
        log.t_ns.copy(),
        log.x.copy(),
        log.y.copy(),
        log.yaw.copy(),
        parent_frame=log.parent_frame,
        child_frame=log.child_frame,
    )
    mounts = {
        n: SensorMount(float(sub.x[i]), float(sub.y[i]), float(sub.yaw[i]))
        for i, n in enumerate(sub.names)
    }
    echo = ranges[np.isfinite(ranges) & (ranges < sub.max_range)]
    notes.append(
        f"{ranges.size} readings: {echo.size} echoes, "
        f"{int(np.count_nonzero(ranges >= sub.max_range))} at max range, "
        f"{int(np.count_nonzero(np.isneginf(ranges)))} too close (−inf)"
    )
    content = LogContent(batch, sub.names, poses, mounts)
    return Emulation(content, ranges, sub, dropped, tuple(notes))


# --------------------------------------------------------------------------- laser map


@dataclass(frozen=True)
class LaserMapOptions:
    """Ray casting of the reference laser map (m; log-odds per observation)."""

    resolution: float = 0.05
    margin: float = 0.5  # around the poses and endpoints
    max_free_range: float = 30.0  # no-return beams clear free space up to this, m
    p_occ: float = 0.9  # inverse sensor model at the endpoint cell
    p_free: float = 0.4  # ... and along the beam
    max_cells: int = 50_000_000


@dataclass(frozen=True)
class LaserMap:
    """The laser occupancy grid: probability (NaN unknown), per-cell hit and pass counts."""

    probability: F32
    grid: GridSpec
    hits: I32
    passes: I32


def laser_occupancy_map(log: LaserLog, options: LaserMapOptions | None = None) -> LaserMap:
    """Log-odds map of every beam cast from the laser pose (vectorised sampling at half a
    cell): each beam counts once per cell it crosses as free, its endpoint cell (a return
    below the laser max) as occupied; L = hits·logit(p_occ) + passes·logit(p_free), summed
    without clamping so the map does not depend on the scan order."""
    opt = options if options is not None else LaserMapOptions()
    res = opt.resolution
    if not res > 0:
        raise ConfigError(f"laser map resolution must be > 0, got {res!r}")
    lx, ly, lyaw = log.laser_poses()
    valid = log.valid_returns()
    th = lyaw[:, None] + log.angles
    cos, sin = np.cos(th), np.sin(th)
    r = log.ranges
    hx = (lx[:, None] + r * cos)[valid]
    hy = (ly[:, None] + r * sin)[valid]
    xs = np.concatenate([lx, hx])
    ys = np.concatenate([ly, hy])
    grid = GridSpec.covering(
        float(xs.min()) - opt.margin,
        float(ys.min()) - opt.margin,
        float(xs.max()) + opt.margin,
        float(ys.max()) + opt.margin,
        res,
    )
    if grid.width * grid.height > opt.max_cells:
        raise InputError(
            f"laser map would have {grid.width}×{grid.height} cells (> {opt.max_cells}); "
            "use a coarser resolution"
        )
    n_cells = grid.width * grid.height

    def cell_of(x: F64, y: F64) -> I64:
        c = np.floor((x - grid.origin_x) / res).astype(np.int64)
        rr = np.floor((y - grid.origin_y) / res).astype(np.int64)
        inside = (c >= 0) & (c < grid.width) & (rr >= 0) & (rr < grid.height)
        return np.where(inside, rr * grid.width + c, -1)

    hit_cell = cell_of(hx, hy)
    hits = np.bincount(hit_cell[hit_cell >= 0], minlength=n_cells)

    # Free length per beam: to the echo, or up to the cap for no-return beams.
    with np.errstate(invalid="ignore"):
        no_return = (r >= log.range_max[:, None]) | np.isposinf(r)
    cap = np.minimum(log.range_max, opt.max_free_range)[:, None]
    length = np.where(valid, r, np.where(no_return, cap, 0.0))
    end_cell = np.full(r.shape, -1, np.int64)
    end_cell[valid] = hit_cell
    beams = np.nonzero(length.reshape(-1) > 0)[0]
    length_b = length.reshape(-1)[beams]
    step = 0.5 * res
    count = np.ceil(length_b / step).astype(np.int64)
    scan_b = beams // r.shape[1]
    ox, oy = lx[scan_b], ly[scan_b]
    cb, sb = cos.reshape(-1)[beams], sin.reshape(-1)[beams]
    endb = end_cell.reshape(-1)[beams]
    passes = np.zeros(n_cells, np.int64)
    bounds = np.concatenate([[0], np.cumsum(count)])
    cuts = np.searchsorted(bounds, np.arange(0, int(bounds[-1]), _CHUNK_CELLS), side="right") - 1
    cuts = np.unique(np.concatenate([cuts, [beams.shape[0]]]))
    for a, b in zip(cuts[:-1].tolist(), cuts[1:].tolist(), strict=True):
        n = count[a:b]
        rep = np.repeat(np.arange(a, b), n)
        k = np.arange(int(n.sum())) - np.repeat(bounds[a:b] - bounds[a], n)
        s = k * step
        cell = cell_of(ox[rep] + s * cb[rep], oy[rep] + s * sb[rep])
        # A beam crosses each cell in one run of samples: count the first of each run.
        first = np.ones(cell.shape, bool)
        first[1:] = (cell[1:] != cell[:-1]) | (rep[1:] != rep[:-1])
        use = first & (cell >= 0) & (cell != endb[rep])
        passes += np.bincount(cell[use], minlength=n_cells)
    l_occ = math.log(opt.p_occ / (1 - opt.p_occ))
    l_free = math.log(opt.p_free / (1 - opt.p_free))
    logodds = hits * l_occ + passes * l_free
    prob = 1.0 / (1.0 + np.exp(-logodds))
    prob[(hits + passes) == 0] = np.nan
    shape = grid.shape
    return LaserMap(
        prob.reshape(shape).astype(np.float32),
        grid,
        hits.reshape(shape).astype(np.int32),
        passes.reshape(shape).astype(np.int32),
    )


# --------------------------------------------------------------------------- writing


def output_paths(out_path: Path) -> tuple[Path, Path, Path]:
    """``<stem>.laser.yaml``, ``<stem>.laser.pgm`` and ``<stem>.truth.csv`` beside a log."""
    return reference_paths(out_path, "laser")


def write_emulation(
    em: Emulation,
    laser_map: LaserMap,
    out_path: str | Path,
    fmt: str,
    *,
    compression: str = "none",
) -> list[Path]:
    """Write the sonar log, the laser map and the trajectory; return the paths (log first).

    Refuses (OutputError) when any of them exists already, before writing anything.
    """
    return write_log_with_reference(
        em.content, out_path, fmt, compression=compression, kind="laser",
        probability=laser_map.probability, grid=laser_map.grid, trajectory=em.content.poses,
    )


@dataclass(frozen=True)
class EmulateOptions:
    """Options of :func:`run_emulation` (None = from the mounts / the configuration)."""

    preset: str | None = None
    fov_deg: float | None = None
    max_range: float | None = None
    require_full_cone: bool = False
    max_scans: int | None = None
    laser_topic: str | None = None
    laser_max_range: float | None = None
    map_resolution: float | None = None  # default: [grid] resolution of the config
    max_free_range: float = 30.0
    compression: str = "none"


@dataclass(frozen=True)
class EmulationResult:
    """What :func:`run_emulation` wrote and found."""

    paths: list[Path]
    scans: int
    readings: int
    sonars: tuple[str, ...]
    notes: tuple[str, ...] = field(default_factory=tuple)
    map_shape: tuple[int, int] = (0, 0)


def run_emulation(
    laser_path: str | Path,
    out_path: str | Path,
    fmt: str = "mcap",
    *,
    config: Config | None = None,
    options: EmulateOptions | None = None,
) -> EmulationResult:
    """The ``sonarmap emulate`` command: read the laser log, emulate the ring, write."""
    cfg = config if config is not None else Config()
    opt = options if options is not None else EmulateOptions()
    out = Path(out_path)
    # Refuse existing outputs before the (slow) reading and emulation.
    for q in (out, *output_paths(out)):
        if q.exists() or q.is_symlink():
            raise OutputError("exists already, not overwriting", q)
    ring = ring_from_mounts(
        mounts_from_config(cfg, opt.preset),
        fov_deg=opt.fov_deg,
        max_range=opt.max_range,
        default_fov_deg=cfg.sensors.fov_deg or DEFAULT_FOV_DEG,
        default_min_range=cfg.sensors.min_range,
        default_max_range=cfg.sensors.max_range or DEFAULT_MAX_RANGE_M,
    )
    log = load_laser_log(
        laser_path,
        cfg,
        max_scans=opt.max_scans,
        laser_topic=opt.laser_topic,
        laser_max_range=opt.laser_max_range,
    )
    em = emulate(log, ring, require_full_cone=opt.require_full_cone)
    lmap = laser_occupancy_map(
        log,
        LaserMapOptions(
            resolution=opt.map_resolution or cfg.grid.resolution,
            max_free_range=opt.max_free_range,
            max_cells=cfg.grid.max_cells,
        ),
    )
    paths = write_emulation(em, lmap, out, fmt, compression=opt.compression)
    return EmulationResult(
        paths=paths,
        scans=len(log),
        readings=len(em.content.ranges),
        sonars=em.ring.names,
        notes=em.notes,
        map_shape=lmap.grid.shape,
    )
