"""CARMEN log files: front laser scans (``FLASER``), odometry (``ODOM``) and ``PARAM`` lines.

The CARMEN text format has one message per line, fields separated by whitespace:

* ``FLASER n r_1 … r_n x y theta odom_x odom_y odom_theta timestamp host logger_timestamp``
  — ``n`` ranges (m) of the front laser; ``x y theta`` is the laser pose in the world (in
  the Radish "corrected" logs the SLAM-corrected pose), ``odom_*`` the raw odometry pose
  (m, rad); ``timestamp`` in seconds.
* ``ODOM x y theta tv rv accel timestamp host logger_timestamp`` (m, rad, m/s, rad/s).
* ``PARAM name value host timestamp``.

Beam angles: the ``n`` beams spread evenly over the laser's field of view (PARAM
``laser_front_laser_fov``, default 180°; in degrees as CARMEN's ini writes it, in radians
where it is at most 2π, 6.3 as a log rounds it — no scanning laser spans under 6.3°, and
MIT CSAIL's log writes ``3.14159`` for its 361 beams at 0.5°), starting at −fov/2. An even ``n``
(180, 360) spaces them by fov/n (180 beams: −90° + i·1°, the SICK LMS in 1° mode as CARMEN
logs it); an odd ``n`` (181, 361) by fov/(n − 1), so the last beam is at +fov/2.
``robot_frontlaser_offset`` (m, along the robot's x axis) places the laser in the base
frame. Ranges at or above the laser's maximum (PARAM ``robot_front_laser_max``, default
81.83 m — the SICK LMS "no return" code) are no return.

Logs may be gzip-compressed. Comment lines (``#``) and blank lines are skipped, and so are
the other message types (counted in :attr:`CarmenLog.skipped`). Malformed lines raise
:class:`~formats.errors.FormatError` naming the file and the line number.
"""

from __future__ import annotations

import gzip
import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from formats.arrays import F64, I64
from formats.contract import SensorMount
from formats.errors import FormatError
from formats.magic import GZIP_MAGIC
from formats.stamps import parse_time

DEFAULT_FOV_DEG = 180.0
DEFAULT_LASER_MAX_M = 81.83  # SICK LMS "no return" value as CARMEN logs it
# Message names of CARMEN's logger (carmen/src/logtools), used to recognise a CARMEN log.
KNOWN_MESSAGES = frozenset(
    {
        "PARAM",
        "SYNC",
        "ODOM",
        "FLASER",
        "RLASER",
        "LASER3",
        "LASER4",
        "TRUEPOS",
        "ROBOTLASER1",
        "ROBOTLASER2",
        "RAWLASER1",
        "RAWLASER2",
        "RAWLASER3",
        "RAWLASER4",
        "NMEAGGA",
        "NMEARMC",
        "GPSNMEA",
        "SONAR",
        "BUMPER",
        "IMU",
        "VECTORMOVE",
        "NEFF",
    }
)
FOV_PARAMS = ("laser_front_laser_fov",)
MAX_RANGE_PARAMS = ("robot_front_laser_max", "laser_front_laser_max_range")
OFFSET_PARAM = "robot_frontlaser_offset"


@dataclass(frozen=True)
class CarmenLaser:
    """FLASER scans as columns: ``S`` scans of ``B`` beams (m, rad, ns).

    ``x, y, yaw``: the laser pose in the world frame logged with each scan;
    ``odom_x, odom_y, odom_yaw``: the raw odometry pose; ``line``: 1-based line numbers.
    """

    t_ns: I64  # (S,)
    ranges: F64  # (S, B)
    angles: F64  # (B,) beam angles in the laser frame
    x: F64
    y: F64
    yaw: F64
    odom_x: F64
    odom_y: F64
    odom_yaw: F64
    line: I64
    max_range: float  # readings >= this are no return
    fov_rad: float

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])


@dataclass(frozen=True)
class CarmenOdom:
    """ODOM lines as columns (m, rad, m/s, rad/s, ns)."""

    t_ns: I64
    x: F64
    y: F64
    yaw: F64
    tv: F64
    rv: F64

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])


@dataclass(frozen=True)
class CarmenLog:
    """What :func:`read_carmen` found in a CARMEN log."""

    path: Path
    laser: CarmenLaser
    odom: CarmenOdom
    params: dict[str, str]
    laser_mount: SensorMount  # front laser in the base frame (robot_frontlaser_offset)
    skipped: dict[str, int] = field(default_factory=dict)  # other message types → lines


def _open_text(path: Path) -> str:
    """The whole log as text, gunzipped when it starts with the gzip magic."""
    try:
        data = path.read_bytes()
    except FileNotFoundError as err:
        raise FormatError("no such file", path) from err
    except OSError as err:
        raise FormatError(f"cannot read: {err.strerror or err}", path) from err
    if data.startswith(GZIP_MAGIC):
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError, zlib.error) as err:
            raise FormatError(f"corrupt or truncated gzip data: {err}", path) from err
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise FormatError(f"not a text log (byte {err.start} is not UTF-8)", path) from err


def looks_like_carmen(path: str | Path) -> bool:
    """Whether the first message line of a (possibly gzipped) file is a CARMEN message."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            head = f.read(4096)
        if head.startswith(GZIP_MAGIC):
            with gzip.open(p, "rb") as g:
                head = g.read(4096)
    except (OSError, EOFError, zlib.error):
        return False
    for raw in head.split(b"\n")[:50]:
        s = raw.strip()
        if not s or s.startswith(b"#"):
            continue
        return s.split()[0].decode("ascii", "replace") in KNOWN_MESSAGES
    return False


def _seconds_to_ns(text: str, path: Path, line: int) -> int:
    """Decimal seconds to integer ns, exactly (:func:`formats.stamps.parse_time`)."""
    try:
        return parse_time(text)
    except ValueError as err:
        raise FormatError(f"line {line}: timestamp: {err}", path) from None


def _numbers(
    rows: list[list[str]], cols: list[int], lines: list[int], path: Path, what: str
) -> F64:
    """Columns ``cols`` of token rows as floats, one row per line; errors name the line."""
    table = [[r[c] for c in cols] for r in rows]
    try:
        return np.array(table, dtype=np.float64).reshape(len(rows), len(cols))
    except ValueError:
        for r, ln in zip(table, lines, strict=True):
            for tok in r:
                try:
                    float(tok)
                except ValueError:
                    raise FormatError(
                        f"line {ln}: {what} field {tok!r} is not a number", path
                    ) from None
        raise  # pragma: no cover - numpy refused what float() accepts


def _param_float(params: dict[str, str], names: tuple[str, ...], path: Path) -> float | None:
    for name in names:
        if name in params:
            try:
                return float(params[name])
            except ValueError as err:
                raise FormatError(f"PARAM {name} is not a number: {params[name]!r}", path) from err
    return None


def laser_fov_rad(value: float | None, path: Path) -> float:
    """The laser's field of view (rad) from PARAM ``laser_front_laser_fov`` (None: absent):
    radians where it is at most 2π as a log rounds it (6.3), else degrees (module doc)."""
    if value is None:
        return math.radians(DEFAULT_FOV_DEG)
    fov = min(value, 2 * math.pi) if value <= 6.3 else math.radians(value)
    if not 0 < fov <= 2 * math.pi:
        raise FormatError(
            f"laser field of view {value:g} (PARAM {FOV_PARAMS[0]}) is not in (0, 360] "
            "degrees or (0, 2π] radians", path)
    return fov


def beam_angles(n: int, fov_rad: float) -> F64:
    """Beam angles (rad) of ``n`` beams over ``fov_rad``, CARMEN's convention (module doc)."""
    step = fov_rad / n if n % 2 == 0 else fov_rad / max(n - 1, 1)
    return -0.5 * fov_rad + step * np.arange(n, dtype=np.float64)


def read_carmen(
    path: str | Path, *, max_scans: int | None = None, laser_max_range: float | None = None
) -> CarmenLog:
    """Parse a CARMEN log (plain or gzip). ``max_scans`` keeps only the first scans;
    ``laser_max_range`` (m) overrides the PARAM/default laser maximum."""
    p = Path(path)
    text = _open_text(p)
    flaser: list[list[str]] = []
    flaser_lines: list[int] = []
    odom: list[list[str]] = []
    odom_lines: list[int] = []
    params: dict[str, str] = {}
    skipped: dict[str, int] = {}
    recognised = 0
    for ln, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        tokens = s.split()
        kind = tokens[0]
        if kind == "FLASER":
            if max_scans is not None and len(flaser) >= max_scans:
                continue
            flaser.append(tokens)
            flaser_lines.append(ln)
        elif kind == "ODOM":
            odom.append(tokens)
            odom_lines.append(ln)
        elif kind == "PARAM":
            if len(tokens) < 3:
                raise FormatError(f"line {ln}: PARAM needs a name and a value", p)
            params[tokens[1]] = tokens[2]
        else:
            if kind not in KNOWN_MESSAGES and recognised == 0 and not skipped:
                raise FormatError(
                    f"line {ln}: not a CARMEN log (first message is {kind[:40]!r})", p
                )
            skipped[kind] = skipped.get(kind, 0) + 1
            continue
        recognised += 1
    if recognised == 0 and not skipped:
        raise FormatError("no CARMEN messages (empty log)", p)

    fov = laser_fov_rad(_param_float(params, FOV_PARAMS, p), p)
    pmax = _param_float(params, MAX_RANGE_PARAMS, p)
    max_range = laser_max_range if laser_max_range is not None else (pmax or DEFAULT_LASER_MAX_M)
    offset = _param_float(params, (OFFSET_PARAM,), p) or 0.0
    laser = _parse_flaser(flaser, flaser_lines, p, fov, float(max_range))
    return CarmenLog(
        path=p,
        laser=laser,
        odom=_parse_odom(odom, odom_lines, p),
        params=params,
        laser_mount=SensorMount(offset, 0.0, 0.0),
        skipped=skipped,
    )


def _parse_flaser(
    rows: list[list[str]], lines: list[int], path: Path, fov: float, max_range: float
) -> CarmenLaser:
    if not rows:
        e = np.empty(0, np.float64)
        return CarmenLaser(
            np.empty(0, np.int64),
            np.empty((0, 0)),
            e,
            e,
            e,
            e,
            e,
            e,
            e,
            np.empty(0, np.int64),
            max_range,
            fov,
        )
    n_beams = -1
    for r, ln in zip(rows, lines, strict=True):
        if len(r) < 2 or not r[1].isdigit():
            raise FormatError(f"line {ln}: FLASER beam count {r[1:2]} is not an integer", path)
        n = int(r[1])
        if len(r) != n + 11:
            raise FormatError(
                f"line {ln}: FLASER has {len(r)} fields, expected {n + 11} for {n} beams", path
            )
        if n_beams < 0:
            n_beams = n
        elif n != n_beams:
            raise FormatError(
                f"line {ln}: FLASER has {n} beams, earlier scans have {n_beams}", path
            )
    if n_beams == 0:
        raise FormatError(f"line {lines[0]}: FLASER has no beams", path)
    vals = _numbers(rows, list(range(2, n_beams + 8)), lines, path, "FLASER")
    t_ns = np.array(
        [_seconds_to_ns(r[n_beams + 8], path, ln) for r, ln in zip(rows, lines, strict=True)],
        np.int64,
    )
    pose = vals[:, n_beams:]
    return CarmenLaser(
        t_ns=t_ns,
        ranges=np.ascontiguousarray(vals[:, :n_beams]),
        angles=beam_angles(n_beams, fov),
        x=pose[:, 0].copy(),
        y=pose[:, 1].copy(),
        yaw=pose[:, 2].copy(),
        odom_x=pose[:, 3].copy(),
        odom_y=pose[:, 4].copy(),
        odom_yaw=pose[:, 5].copy(),
        line=np.asarray(lines, np.int64),
        max_range=max_range,
        fov_rad=fov,
    )


def _parse_odom(rows: list[list[str]], lines: list[int], path: Path) -> CarmenOdom:
    for r, ln in zip(rows, lines, strict=True):
        if len(r) != 10:
            raise FormatError(f"line {ln}: ODOM has {len(r)} fields, expected 10", path)
    vals = _numbers(rows, [1, 2, 3, 4, 5], lines, path, "ODOM") if rows else np.empty((0, 5))
    t_ns = np.array(
        [_seconds_to_ns(r[7], path, ln) for r, ln in zip(rows, lines, strict=True)], np.int64
    )
    return CarmenOdom(
        t_ns,
        vals[:, 0].copy(),
        vals[:, 1].copy(),
        vals[:, 2].copy(),
        vals[:, 3].copy(),
        vals[:, 4].copy(),
    )
