"""A generated log (simulated or emulated) written with what it is scored against: the
reference map (nav2 YAML + PGM) and the true trajectory CSV: all written or none."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Protocol

import numpy as np

from formats.arrays import F64, I64
from formats.errors import OutputError
from formats.log_writers import LogContent, write_log
from formats.map_types import GridSpec
from formats.writers.atomic import atomic_write_text
from formats.writers.nav2_map import write_nav2_map
from formats.writers.trajectory_csv import trajectory_csv_text


class StampedPoses(Protocol):
    """Poses with stamps: ``t_ns`` (ns) and ``x``, ``y`` (m), ``yaw`` (rad)."""

    @property
    def t_ns(self) -> I64: ...
    @property
    def x(self) -> F64: ...
    @property
    def y(self) -> F64: ...
    @property
    def yaw(self) -> F64: ...


_LOG_SUFFIXES = frozenset({".mcap", ".bag", ".db3", ".csv", ".txt"})


def reference_paths(out_path: Path, kind: str) -> tuple[Path, Path, Path]:
    """``<stem>.<kind>.yaml``, ``<stem>.<kind>.pgm`` and ``<stem>.truth.csv`` beside a log;
    the stem is the name without its log suffix only (``sim_0.02_0.0.mcap`` →
    ``sim_0.02_0.0``), so logs whose names differ after a dot do not share truth files."""
    name = out_path.name
    stem = name[: -len(out_path.suffix)] if out_path.suffix.lower() in _LOG_SUFFIXES else name
    stem = stem or name
    d = out_path.parent
    return d / f"{stem}.{kind}.yaml", d / f"{stem}.{kind}.pgm", d / f"{stem}.truth.csv"


def write_log_with_reference(
    content: LogContent,
    out_path: str | Path,
    fmt: str,
    *,
    compression: str,
    kind: str,
    probability: np.ndarray,
    grid: GridSpec,
    trajectory: StampedPoses,
) -> list[Path]:
    """A log plus what it is scored against: the reference map (nav2 YAML + PGM, see
    :func:`reference_paths`) and the trajectory CSV ``t,x,y,yaw`` (t as exact decimal
    seconds, floats that round-trip exactly). Returns the paths, log first.

    Refuses (OutputError) when any of them exists already, before writing anything.
    """
    out = Path(out_path)
    yaml_path, pgm_path, csv_path = reference_paths(out, kind)
    for q in (out, yaml_path, pgm_path, csv_path):
        if q.exists() or q.is_symlink():
            raise OutputError("exists already, not overwriting", q)
    try:
        log_path = write_log(content, out, fmt, compression=compression)
        tp = trajectory
        atomic_write_text(csv_path, trajectory_csv_text(tp.t_ns, tp.x, tp.y, tp.yaw))
        write_nav2_map(yaml_path, probability, grid)
    except BaseException:
        # All or nothing: every one of these names was free before (checked above).
        for q in (out, csv_path, yaml_path, pgm_path):
            if q.is_dir() and not q.is_symlink():
                shutil.rmtree(q, ignore_errors=True)
            else:
                q.unlink(missing_ok=True)
        raise
    return [log_path, yaml_path, pgm_path, csv_path]
