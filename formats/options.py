"""What a reader needs to know besides the log: the ``[input]`` and ``[sensors]`` sections.

These are sections of the run's configuration (:class:`pipeline.config.Config` holds them),
defined here, on the ground floor, so that readers take them without reaching up into
``pipeline/``. Each field's ``doc`` metadata is the comment ``sonarmap config`` prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Protocol


def doc_field(text: str, **kw: Any) -> Any:
    """A dataclass field whose ``doc`` metadata is its one-line description."""
    return field(metadata={"doc": text}, **kw)


@dataclass(frozen=True)
class CsvConfig:
    """How to read CSV/text logs (see formats/csv_log.py for the schema)."""

    layout: Literal["single", "set"] = doc_field(
        "'single': one file, a row per reading (t, x, y, yaw, sensor, range); "
        "'set': separate ranges/poses/sensors files",
        default="single",
    )
    ranges_file: str = doc_field("set layout: ranges file, relative to the log directory", default="ranges.csv")
    poses_file: str = doc_field("set layout: poses file, relative to the log directory", default="poses.csv")
    sensors_file: str = doc_field(
        "set layout: sensors file (optional; missing = mounts from [sensors])", default="sensors.csv"
    )
    wide_ranges: bool = doc_field(
        "ranges file has one column per sensor (t, r_0, r_1, ...) instead of a row per reading",
        default=False,
    )
    delimiter: str = doc_field("field delimiter; 'whitespace' for runs of spaces/tabs", default=",")
    header: bool = doc_field("first line names the columns", default=True)
    time_unit: Literal["s", "ms", "us", "ns"] = doc_field("unit of time columns", default="s")
    length_unit: Literal["m", "cm", "mm"] = doc_field("unit of x, y and ranges", default="m")
    angle_unit: Literal["rad", "deg", "tenths"] = doc_field(
        "unit of yaw ('tenths' = tenths of a degree)", default="rad"
    )
    no_echo_value: float = doc_field(
        "a range equal to this (in length_unit) means no echo (+inf); negative = none",
        default=-1.0,
    )


@dataclass(frozen=True)
class InputConfig:
    """Which format and topics to read."""

    format: str = doc_field("log format; '' = detect from content", default="")
    range_topics: tuple[str, ...] = doc_field("range topics; empty = discover by type", default=())
    pose_topic: str = doc_field("pose topic ('/tf' for tf); '' = discover by type", default="")
    base_frame: str = doc_field("robot base frame (REP 105)", default="base_link")
    max_file_gap_s: float = doc_field(
        "a recording given as several files: the largest gap, s, between one file's end and "
        "the next file's start (split bags follow each other, sonar/odometry bags overlap)",
        default=10.0,
    )
    csv: CsvConfig = field(default_factory=CsvConfig)


# A sensor's name (a ROS frame id, a CSV sensor column, a config mount): longer is no name.
MAX_NAME_CHARS = 256

# Beam widths sonarmap maps with, wherever they come from (config, preset, log): narrower
# beams are no sonar (and leave no cell to free), 180° and wider have no cone.
FOV_MIN_DEG = 0.5
FOV_MAX_DEG = 180.0  # exclusive


@dataclass(frozen=True)
class MountConfig:
    """One sonar: mount in the base frame and beam limits."""

    name: str = doc_field("sensor name (frame id of its Range messages)", default="")
    x: float = doc_field("mount x in base frame, m", default=0.0)
    y: float = doc_field("mount y in base frame, m", default=0.0)
    yaw_deg: float = doc_field("beam axis in base frame, degrees", default=0.0)
    fov_deg: float = doc_field("full beam width β, degrees; 0 = from the log", default=0.0)
    min_range: float = doc_field("r_min, m; 0 = from the log", default=0.0)
    max_range: float = doc_field("r_max, m; 0 = from the log", default=0.0)


@dataclass(frozen=True)
class SensorsConfig:
    """Sensor mounts: explicit entries, a preset, or /tf_static from the log."""

    preset: str = doc_field(
        "mount preset ('pioneer-p3dx', 'pioneer-p3dx-front', 'udacity-8sonar', "
        "'hc-sr04-sweep3'); '' = none", default=""
    )
    fov_deg: float = doc_field("default beam width β where the log has none, degrees", default=0.0)
    min_range: float = doc_field("default r_min where the log has none, m", default=0.0)
    max_range: float = doc_field("default r_max where the log has none, m", default=0.0)
    mounts: tuple[MountConfig, ...] = ()


@dataclass(frozen=True)
class ReaderOptions:
    """The configuration a reader takes: ``[input]`` and ``[sensors]`` (defaults: both empty).

    The run's :class:`pipeline.config.Config` has the same two sections and is passed as is.
    """

    input: InputConfig = field(default_factory=InputConfig)
    sensors: SensorsConfig = field(default_factory=SensorsConfig)


class ReaderSettings(Protocol):
    """Anything with ``input`` and ``sensors`` sections: :class:`ReaderOptions` or a Config."""

    @property
    def input(self) -> InputConfig: ...

    @property
    def sensors(self) -> SensorsConfig: ...
