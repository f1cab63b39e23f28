"""A run that maps (almost) no reading is an error, naming the cause and the fix.

Exit 0 with an empty map hides a broken input (1 Hz odometry under a 0.5 s pose gap limit,
poses and readings that do not overlap in time, sensors that never echo). A run must map
at least MIN_MAPPED_FRACTION of its readings; a reading is *mapped* when it became an
echo (a feature or an occupied update) or, with ``clear_on_max_range``, cleared free space
as a no-echo reading.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from formats.errors import InputError
from pipeline.config import Config

MIN_MAPPED_FRACTION = 0.01  # 1 % of the readings
_NO_ECHO = ("max_range", "pos_inf")


def mapped_readings(used: int, dropped: Mapping[str, int], clear_on_max_range: bool) -> int:
    """Readings that went into the map (see the module docstring)."""
    return used + (sum(int(dropped.get(r, 0)) for r in _NO_ECHO) if clear_on_max_range else 0)


def _fix(reason: str, gap_s: float, median_s: float, config: Config) -> str:
    """What to change for readings dropped for ``reason``."""
    if reason == "in_pose_gap":
        if config.pose_sync.max_pose_gap_s > 0:
            return (f"they fall in gaps between poses longer than [pose_sync] max_pose_gap_s = "
                    f"{gap_s:g} s while the poses are {median_s:.3g} s apart (median): raise "
                    "max_pose_gap_s, or set it to 0 for the automatic limit")
        return (f"they fall in gaps between poses longer than the automatic limit {gap_s:g} s "
                f"(the poses are {median_s:.3g} s apart, median): set a larger "
                "[pose_sync] max_pose_gap_s")
    if reason in ("before_first_pose", "after_last_pose"):
        return ("the readings and the poses do not overlap in time: check the pose topic "
                "(--pose-topic) or [pose_sync] time_offset_s")
    if reason == "pose_jump":
        return "the poses jump faster than a robot moves: check the odometry (sonarmap validate)"
    if reason == "outside_grid":
        return "they lie outside [grid] extent: widen it"
    if reason in _NO_ECHO:
        return ("they are no-echo readings (at max range or +inf): check the sensors' "
                "max_range, or set [mapper] clear_on_max_range = true to map their free space")
    if reason in ("late", "stamp_backwards"):
        return "their stamps are out of order: see sonarmap validate"
    return "they are invalid ranges (REP 117 NaN/-inf, negative, below min_range): see sonarmap validate"


def check_mapped_share(
    log_path: Path | object,
    counts: Mapping[str, int],
    dropped: Mapping[str, int],
    gap_s: float,
    median_s: float,
    config: Config,
) -> None:
    """Raise InputError when fewer than MIN_MAPPED_FRACTION of the readings were mapped."""
    total = int(counts["readings"])
    mapped = int(counts["readings_mapped"])
    if total == 0 or mapped >= MIN_MAPPED_FRACTION * total:
        return
    reason, n = max(sorted(dropped.items()), key=lambda kv: kv[1])
    raise InputError(
        f"only {mapped} of {total} readings could be mapped (at least "
        f"{MIN_MAPPED_FRACTION:.0%} needed); {n} were dropped as {reason}: "
        f"{_fix(reason, gap_s, median_s, config)}",
        log_path,
    )
