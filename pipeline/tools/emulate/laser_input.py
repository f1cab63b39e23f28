"""The laser log ``sonarmap emulate`` reads: scans with the robot pose of each.

CARMEN logs carry each scan's pose; for ROS 1 / ROS 2 / MCAP logs the robot poses (Odometry
or tf, through the ROS reader) are interpolated at the scan stamps. Scans are sorted by
stamp.
"""

from __future__ import annotations

from pathlib import Path

from formats.errors import ConfigError, FormatError, InputError, SonarmapError
from formats.laser_log import LaserLog, read_carmen_laser_log, read_ros_laser_scans, sorted_by_time
from formats.ros.reader import RosLogReader
from formats.storage.location import Location, Url, as_location
from pipeline.config import Config
from pipeline.stages.pose_sync import POSE_OK, build_pose_track, interpolate_poses, pose_gap_limit_s


def load_laser_log(
    path: str | Location,
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
    from formats.magic import MCAP_MAGIC, ROS1_MAGIC

    cfg = config if config is not None else Config()
    p = as_location(path)
    if max_scans is not None and max_scans < 1:
        raise ConfigError(f"max_scans must be >= 1, got {max_scans}")
    if not p.exists():
        raise FormatError("no such file or directory", p)
    if isinstance(p, Url) and p.is_file():
        with p.open("rb") as f:
            head = f.read(16)
        if not head.startswith((ROS1_MAGIC, MCAP_MAGIC)):  # CARMEN text: read from a copy
            return _from_local_copy(p, cfg, max_scans, laser_topic, laser_max_range)
    if isinstance(p, Path) and p.is_file():
        with p.open("rb") as f:
            head = f.read(16)
        if not head.startswith(ROS1_MAGIC) and looks_like_carmen(p):
            return sorted_by_time(
                read_carmen_laser_log(p, cfg.input.base_frame, max_scans, laser_max_range)
            )
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
    return sorted_by_time(_load_ros(p, fmt, cfg, max_scans, laser_topic))


def _from_local_copy(
    url: Url, cfg: Config, max_scans: int | None, laser_topic: str | None,
    laser_max_range: float | None,
) -> LaserLog:
    """A laser log at a URL that is not read by ranges, downloaded to a temporary file
    (removed after); errors name the URL."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="sonarmap-laser-") as d:
        local = Path(d) / url.name
        url.download(local)
        try:
            return load_laser_log(local, cfg, max_scans=max_scans, laser_topic=laser_topic,
                                  laser_max_range=laser_max_range)
        except SonarmapError as err:
            raise type(err)(err.reason, url) from None


def _load_ros(
    p: Location, fmt: str, cfg: Config, max_scans: int | None, laser_topic: str | None
) -> LaserLog:
    """Scans of a ROS log with the robot pose interpolated at each scan stamp."""
    from formats import FORMATS

    with FORMATS[fmt](p, cfg) as reader:
        assert isinstance(reader, RosLogReader)
        scans = read_ros_laser_scans(reader, max_scans, laser_topic)
    track = build_pose_track(scans.poses)
    t = scans.t_ns
    notes = list(scans.notes)
    gap_s = pose_gap_limit_s(cfg.pose_sync.max_pose_gap_s, track.median_interval_s())
    look = interpolate_poses(track, t, round(gap_s * 1e9))
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
        ranges=scans.ranges[ok],
        angles=scans.angles[ok],
        range_min=scans.range_min[ok],
        range_max=scans.range_max[ok],
        x=look.x[ok],
        y=look.y[ok],
        yaw=look.yaw[ok],
        laser_mount=scans.laser_mount,
        parent_frame=track.parent_frame,
        child_frame=track.child_frame or cfg.input.base_frame,
        source_format=fmt,
        notes=tuple(notes),
    )
