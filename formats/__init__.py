"""Readers and writers of the logs and maps sonarmap works with.

Entry point: :func:`open_log` returns a :class:`~formats.contract.LogReader` for any
supported log. The format is detected from the content (magic bytes, a rosbag2
``metadata.yaml``, a CSV header), not from the suffix; ``[input] format`` (``--format``)
overrides the guess.
The registry :data:`FORMATS` maps each format name to the function that opens it: an
explicit table, no plugin discovery.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from formats.contract import LogReader
from formats.errors import FormatError
from formats.magic import MCAP_MAGIC, ROS1_MAGIC, SQLITE_MAGIC, ZSTD_MAGIC
from formats.options import ReaderOptions, ReaderSettings
from formats.storage.location import Location, Url, as_location

if TYPE_CHECKING:
    from formats.ros.source import MessageSource


def _ros1_source(path: Location) -> MessageSource:
    from formats.ros.ros1bag import Ros1BagSource

    return Ros1BagSource(path)


def _ros2_source(path: Location) -> MessageSource:
    from formats.ros.ros2bag import Ros2BagSource

    return Ros2BagSource(path)


def _mcap_source(path: Location) -> MessageSource:
    from formats.ros.mcap_source import McapSource

    return McapSource(path)


#: The ROS formats: a message container each, read by one RosLogReader.
SOURCES: dict[str, Callable[[Location], MessageSource]] = {
    "ros1": _ros1_source,
    "ros2": _ros2_source,
    "mcap": _mcap_source,
}


def _open_ros(name: str) -> Callable[[Location, ReaderSettings], LogReader]:
    def open_ros(path: Location, config: ReaderSettings) -> LogReader:
        from formats.ros.reader import RosLogReader

        return RosLogReader(SOURCES[name](path), config)

    return open_ros


def _open_csv(path: Location, config: ReaderSettings) -> LogReader:
    from formats.csv_log import CsvLogReader

    return CsvLogReader(path, config)


FORMATS: dict[str, Callable[[Location, ReaderSettings], LogReader]] = {
    "ros1": _open_ros("ros1"),
    "ros2": _open_ros("ros2"),
    "mcap": _open_ros("mcap"),
    "csv": _open_csv,
}


def check_log_path(p: Location) -> None:
    """Refuse what is not a log file or directory, with the reason: a missing path, a
    symlink loop, a FIFO, socket or device (reading one would hang or never end), a
    rosbag2 ``metadata.yaml`` given instead of its bag directory. A URL must name an
    object, or a prefix holding a bag (a StorageError says why it cannot be reached)."""
    if isinstance(p, Url):
        if p.name == "metadata.yaml":
            raise FormatError(f"is a rosbag2 bag's metadata file; pass the bag directory "
                              f"{p.parent} instead", p)
        if not (p.exists() or p.is_dir()):  # the URL itself first: errors name it
            raise FormatError("no such object or prefix (HTTP 404)", p)
        return
    try:
        st = p.stat()
    except FileNotFoundError as err:
        if p.is_symlink():
            raise FormatError("is a symlink to a missing file", p) from err
        raise FormatError("no such file or directory", p) from err
    except OSError as err:  # ELOOP: a symlink loop; EACCES ...
        raise FormatError(f"cannot open: {err.strerror or err}", p) from err
    import stat

    if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
        raise FormatError("is not a regular file or directory (a FIFO, socket or device); "
                          "give a log file or a bag directory", p)
    if p.name == "metadata.yaml" and stat.S_ISREG(st.st_mode):
        raise FormatError(f"is a rosbag2 bag's metadata file; pass the bag directory "
                          f"{p.parent} instead", p)


def detect_format(path: str | Location) -> str:
    """The format name of a log, from its content. Raises FormatError when unknown."""
    p = as_location(path)
    check_log_path(p)
    if isinstance(p, Url) and (p / "metadata.yaml").is_file():
        return "ros2"  # a bag directory as a URL prefix (HTTP has no directories)
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return "ros2"
        from formats.csv_log import looks_like_csv

        if looks_like_csv(p):
            return "csv"
        raise FormatError(
            "directory is neither a rosbag2 bag (no metadata.yaml) nor a CSV log set", p
        )
    try:
        with p.open("rb") as f:
            head = f.read(64)
    except OSError as err:
        raise FormatError(f"cannot read: {err.strerror or err}", p) from err
    if not head:
        raise FormatError("empty file (0 bytes)", p)
    if head.startswith(ROS1_MAGIC):
        return "ros1"
    if head.startswith(MCAP_MAGIC):
        # A single MCAP file inside a rosbag2 directory is read as the bag.
        return "ros2" if (p.parent / "metadata.yaml").is_file() else "mcap"
    if head.startswith(SQLITE_MAGIC) or head.startswith(ZSTD_MAGIC):
        return "ros2"
    if head.startswith(b"#ROSBAG"):
        version = head.split(b"\n", 1)[0].decode("ascii", "replace")
        raise FormatError(f"unsupported ROS bag version '{version}' (need V2.0)", p)
    from formats.csv_log import looks_like_csv

    if looks_like_csv(p):
        return "csv"
    raise FormatError(
        f"not a recognised log format (starts with {head[:12]!r}): tried ROS 1 bag "
        "('#ROSBAG V2.0'), MCAP (magic bytes), ROS 2 bag (sqlite3, zstd, metadata.yaml) and "
        "CSV (a header of column names such as t,x,y,yaw,sensor,range, or numbers); "
        "pass --format to force one",
        p,
    )


def open_log(
    path: str | Location | Sequence[str | Location], config: ReaderSettings | None = None
) -> LogReader:
    """Open a log for reading; ``config.input.format`` (a key of FORMATS) overrides
    detection.

    Several paths are several files of one recording (split bags, separate sonar and
    odometry bags), read as one log: :class:`~formats.ros.multi_source.MultiSource`.
    """
    cfg = config if config is not None else ReaderOptions()
    if not isinstance(path, str | Path | Url):
        paths = [as_location(p) for p in path]
        if len(paths) != 1:
            return _open_several(paths, cfg)
        path = paths[0]
    p = as_location(path)
    name = cfg.input.format or detect_format(p)
    if name not in FORMATS:
        raise FormatError(f"unknown format '{name}' (known: {', '.join(sorted(FORMATS))})", p)
    check_log_path(p)
    return FORMATS[name](p, cfg)


def _open_several(paths: list[Location], cfg: ReaderSettings) -> LogReader:
    """Several files of one recording as one log (ROS formats only; one format)."""
    from formats.ros.multi_source import MultiSource
    from formats.ros.reader import RosLogReader

    if not paths:
        raise FormatError("no log given")
    seen: dict[Location, Location] = {}
    for p in paths:
        check_log_path(p)
        key = p.resolve()
        if key in seen:
            raise FormatError(f"is given twice (as {seen[key]} and {p})", p)
        seen[key] = p
    names = [cfg.input.format or detect_format(p) for p in paths]
    for p, name in zip(paths, names, strict=True):
        if name not in FORMATS:
            raise FormatError(f"unknown format '{name}' (known: {', '.join(sorted(FORMATS))})", p)
        if name != names[0]:
            raise FormatError(
                f"files of one recording must have one format: {paths[0]} is {names[0]}, "
                f"{p} is {name}"
            )
        if name not in SOURCES:
            raise FormatError(
                f"is a {name} log: several files are read as one recording for ROS 1 bags, "
                "ROS 2 bags and MCAP files; a CSV log is one file, or one directory with "
                "ranges.csv and poses.csv ([input.csv] layout = 'set')", p,
            )
    sources: list[MessageSource] = []
    try:
        for p in paths:
            sources.append(SOURCES[names[0]](p))
    except BaseException:
        for s in sources:
            s.close()
        raise
    return RosLogReader(MultiSource(sources, max_gap_s=cfg.input.max_file_gap_s), cfg)
