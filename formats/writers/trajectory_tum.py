"""``trajectory.csv``: robot poses in the TUM RGB-D trajectory format, which evo reads.

One pose per line, space separated, no trailing delimiter (what ``evo_traj tum`` and
``evo_ape tum`` require)::

    # t x y z qx qy qz qw  (TUM RGB-D; frame: odom; yaw = 2·atan2(qz, qw))
    1700000000.050000000 1.525000000 1.500000000 0 0 0 0.000000000 1.000000000

``t`` is the stamp in seconds, written exactly from the int64 nanoseconds (9 decimals);
``x, y`` in m (9 decimals), ``z = 0``; the orientation is the planar yaw as a unit
quaternion about +z (``qx = qy = 0``, ``qz = sin(yaw/2)``, ``qw = cos(yaw/2)``). Lines that
start with ``#`` are comments (evo skips them). The bytes depend only on the poses.

The API takes plain arrays ``(t_ns, x, y, yaw)`` so that any stage (odometry, a refined
trajectory) writes the same layout; :func:`read_trajectory_tum` reads it back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from formats.angles import yaw_from_quaternion
from formats.arrays import F64, I64
from formats.errors import FormatError
from formats.stamps import format_time_s, parse_time
from formats.text_file import MAX_LIST_BYTES, read_text
from formats.writers.atomic import atomic_open

__all__ = ["Trajectory", "read_trajectory_tum", "write_trajectory_tum"]


_BLOCK = 50_000  # poses formatted at a time (hours of odometry stay small in memory)


@dataclass(frozen=True)
class Trajectory:
    """Planar poses: int64 ns stamps, x and y in m, yaw in rad (−π, π]."""

    t_ns: I64
    x: F64
    y: F64
    yaw: F64

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @property
    def xy(self) -> F64:
        """Positions, N×2 (m)."""
        return np.column_stack([self.x, self.y])


def header_line(frame: str) -> str:
    """The comment line that opens the file (names the columns and the frame)."""
    where = f"frame: {frame}; " if frame else ""
    return f"# t x y z qx qy qz qw  (TUM RGB-D; {where}yaw = 2*atan2(qz, qw))\n"


def _format_block(t_ns: I64, x: F64, y: F64, yaw: F64) -> str:
    yaw = math.pi - np.mod(math.pi - yaw, 2 * math.pi)  # into (−π, π]: −π and π alike
    qz, qw = np.sin(0.5 * yaw), np.cos(0.5 * yaw)
    # One canonical quaternion per yaw (qw ≥ 0): q and −q are the same rotation.
    flip = (qw < 0) | ((qw == 0) & (qz < 0))
    qz, qw = np.where(flip, -qz, qz), np.where(flip, -qw, qw)
    rows = zip(format_time_s(t_ns), x.tolist(), y.tolist(), qz.tolist(), qw.tolist(), strict=True)
    # "+ 0.0" turns −0.0 into 0.0: the same pose always prints the same bytes.
    return "".join(
        f"{t} {px + 0.0:.9f} {py + 0.0:.9f} 0 0 0 {z + 0.0:.9f} {w + 0.0:.9f}\n"
        for t, px, py, z, w in rows
    )


def write_trajectory_tum(
    path: Path,
    t_ns: npt.ArrayLike,
    x: npt.ArrayLike,
    y: npt.ArrayLike,
    yaw: npt.ArrayLike,
    *,
    frame: str = "",
) -> None:
    """Write the poses ``(t_ns, x, y, yaw)`` (equal-length 1-D arrays, any array-like,
    memory-mapped ones included) to ``path`` atomically, in the layout above. ``frame``:
    the frame the poses are in, named in the header comment. ValueError on arrays of
    different lengths or non-finite values (evo would refuse the file)."""
    t = np.asarray(t_ns)
    cols = [np.asarray(c) for c in (x, y, yaw)]
    if t.ndim != 1 or any(c.shape != t.shape for c in cols):
        raise ValueError(
            f"t_ns, x, y, yaw must be 1-D arrays of one length, got shapes "
            f"{t.shape}, {', '.join(str(c.shape) for c in cols)}"
        )
    if not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"t_ns must be integer nanoseconds, got {t.dtype}")
    with atomic_open(Path(path)) as f:
        f.write(header_line(frame).encode("utf-8"))
        for start in range(0, t.shape[0], _BLOCK):
            sl = slice(start, start + _BLOCK)
            bx, by, byaw = (np.asarray(c[sl], dtype=np.float64) for c in cols)
            if not (np.isfinite(bx).all() and np.isfinite(by).all() and np.isfinite(byaw).all()):
                raise ValueError("trajectory has non-finite x, y or yaw")
            f.write(_format_block(np.asarray(t[sl], dtype=np.int64), bx, by, byaw).encode("ascii"))


def read_trajectory_tum(path: Path) -> Trajectory:
    """Read a TUM trajectory (``t x y z qx qy qz qw``, ``#`` comments) as planar poses:
    yaw from the quaternion's rotation about +z. InputError when the file is missing,
    FormatError naming the file and line when a line is not 8 numbers."""
    path = Path(path)
    text = read_text(path, "trajectory file", max_bytes=MAX_LIST_BYTES)
    t: list[int] = []
    vals: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        parts = line.split(" ")
        if len(parts) != 8:
            raise FormatError(
                f"line {lineno}: a TUM pose is 8 space-separated numbers "
                f"(t x y z qx qy qz qw), got {len(parts)} fields", path
            )
        try:
            t.append(parse_time(parts[0]))
            vals.append([float(p) for p in parts[1:]])
        except ValueError:
            raise FormatError(f"line {lineno}: not a number in {line!r}", path) from None
    if not t:
        raise FormatError("trajectory has no poses", path)
    v = np.asarray(vals, dtype=np.float64)
    qx, qy, qz, qw = v[:, 3], v[:, 4], v[:, 5], v[:, 6]
    yaw = yaw_from_quaternion(qx, qy, qz, qw)
    yaw = np.where(yaw <= -math.pi, yaw + 2 * math.pi, yaw)
    return Trajectory(np.asarray(t, dtype=np.int64), v[:, 0].copy(), v[:, 1].copy(), yaw)
