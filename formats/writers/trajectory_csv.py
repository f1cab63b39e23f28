"""The truth trajectory CSV, ``<stem>.truth.csv``: ``t,x,y,yaw`` per pose.

``simulate`` and ``emulate`` write it beside their logs (the true trajectory; with drift,
the log carries the odometry) and ``evaluate --truth-trajectory`` reads it. A run's own
``trajectory.csv`` is TUM (:mod:`formats.writers.trajectory_tum`); :func:`read_trajectory`
reads either, so a truth and a run can be given in any order.

``t`` is exact decimal seconds (``<sec>.<9-digit nsec>`` of the int64 ns stamp), ``x, y``
metres and ``yaw`` radians as Python ``repr`` floats (they round-trip exactly), so a file
written and read back gives the same arrays. Reading accepts a header naming the columns
(any order, extra columns ignored) or none (then the order is ``t,x,y,yaw``); ``#`` lines
are comments.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from formats.errors import FormatError
from formats.stamps import format_time_s, parse_time
from formats.text_file import MAX_LIST_BYTES, read_text
from formats.writers.atomic import atomic_write_text
from formats.writers.trajectory_tum import Trajectory, read_trajectory_tum

COLUMNS = ("t", "x", "y", "yaw")


def trajectory_csv_text(t_ns: npt.ArrayLike, x: npt.ArrayLike, y: npt.ArrayLike,
                        yaw: npt.ArrayLike) -> str:
    """The CSV text of a trajectory (header ``t,x,y,yaw``)."""
    cols = [np.asarray(c, dtype=np.float64).tolist() for c in (x, y, yaw)]
    rows = [
        f"{t},{a!r},{b!r},{c!r}"
        for t, a, b, c in zip(format_time_s(t_ns), *cols, strict=True)
    ]
    return ",".join(COLUMNS) + "\n" + "".join(r + "\n" for r in rows)


def write_trajectory_csv(path: Path, t_ns: npt.ArrayLike, x: npt.ArrayLike, y: npt.ArrayLike,
                         yaw: npt.ArrayLike) -> None:
    """Write a trajectory CSV atomically (replaces ``path``)."""
    atomic_write_text(path, trajectory_csv_text(t_ns, x, y, yaw))


def read_trajectory_csv(path: Path) -> Trajectory:
    """A trajectory CSV as arrays; InputError when missing, FormatError (naming the file and
    the line) when malformed, unsorted or not finite."""
    text = read_text(path, "trajectory file", max_bytes=MAX_LIST_BYTES)
    lines = [
        (i + 1, ln) for i, ln in enumerate(text.splitlines())
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not lines:
        raise FormatError("trajectory is empty", path)
    head = [c.strip().lower() for c in lines[0][1].split(",")]
    if not _is_number(head[0]):  # a header row
        missing = [c for c in COLUMNS if c not in head]
        if missing:
            raise FormatError(f"trajectory header has no {', '.join(missing)} column: "
                              f"{lines[0][1]!r}", path)
        idx = [head.index(c) for c in COLUMNS]
        body = lines[1:]
    else:
        idx, body = [0, 1, 2, 3], lines
    if not body:
        raise FormatError("trajectory has a header but no poses", path)
    n = len(body)
    t = np.empty(n, np.int64)
    vals = np.empty((3, n), np.float64)
    for k, (lineno, ln) in enumerate(body):
        cells = ln.split(",")
        try:
            t[k] = parse_time(cells[idx[0]])
            for j in range(3):
                vals[j, k] = float(cells[idx[j + 1]])
        except (ValueError, IndexError) as err:
            raise FormatError(f"line {lineno}: not a t,x,y,yaw row ({err})", path) from err
    if not np.isfinite(vals).all():
        bad = body[int(np.flatnonzero(~np.isfinite(vals).all(axis=0))[0])][0]
        raise FormatError(f"line {bad}: pose is not finite", path)
    if n > 1 and not (np.diff(t) > 0).all():
        bad = body[int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1][0]
        raise FormatError(f"line {bad}: stamps must increase", path)
    return Trajectory(t, vals[0].copy(), vals[1].copy(), vals[2].copy())


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def read_trajectory(path: Path) -> Trajectory:
    """A trajectory file of either layout sonarmap writes: the CSV ``t,x,y,yaw`` (truth
    files) or TUM (a run's ``trajectory.csv``, :mod:`formats.writers.trajectory_tum`),
    told apart by the first line that is not a comment (commas or not)."""
    lines = read_text(path, "trajectory file", max_bytes=MAX_LIST_BYTES).splitlines()
    first = next((ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")), "")
    if "," in first or not first:
        return read_trajectory_csv(path)
    return read_trajectory_tum(path)
