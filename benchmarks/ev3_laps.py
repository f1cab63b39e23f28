"""Does ``--refine-poses`` make the laps of a real ultrasonic run coincide? (issue 63 item 5)

Usage::

    python -m benchmarks.ev3_laps SPARSE_GSLAM [--runs ev3-69 ...] [--work DIR]
        [--figure PATH] [--config TOML]

``SPARSE_GSLAM`` is a checkout of https://github.com/sg2295/sparse-gslam (``git clone``;
it has no licence, so its data is not copied here) or the directory of its EV3 ``.log``
files (``src/sparse_gslam/datasets/ev3``). A LEGO EV3 rover stops, sweeps one ultrasonic
sensor over 13 directions (−90° … +90°, 15° apart; ``slam.yaml``) and drives on. A line
of a log is ``x y theta`` (cm, cm, rad, REP 103: x ahead, y left, theta counter-clockwise,
unwrapped) and then 13 blocks of ``k`` repeated readings in cm, one block per direction
from −90° (right) up; ``k`` is 10 (ev3-69), 25 (ev3-101, ev3-222, ev3) or 1 (ev3-154,
already averaged), so it is taken from the line's length (sparse-gslam's ``EV3DataProvider``
reads the same layout, but averages each block and applies a piecewise range calibration
capped at 80 cm: neither is done here). 255 cm is the sensor's "no echo".

**Conversion** (:func:`convert`) to a sonarmap CSV set: one virtual sensor per direction
(``ev3_00`` … ``ev3_12`` at the rover's origin, yaw −90° + 15° i, 30° beam, 0.03-2.55 m:
the EV3 sensor's specification); a direction's range is the median of its readings (+inf
if that is ≥ 255 cm); metres; int ns stamps synthesised at one stop per second, direction i
fired at ``i × 50 ms`` into the stop, the pose written at the stop's start and end (the
rover stands while it sweeps).

**Lap spread** (:func:`lap_spread`): echoes (finite, ≤ ``ECHO_RANGE_M``) are placed with
the odometry and with the refined trajectory; a stop's lap is the number of whole turns
its logged heading has made since the start. For each echo, the distance to the nearest
echo of another lap; the table gives the median and 90th percentile of those, unrefined
and refined, and what refinement did (metrics.json). Both ``sonarmap run`` calls take
``CONFIG`` (the EV3's scale; or ``--config``). The spread shrinks with echo density (more
laps, more neighbours), so compare a run's two columns, not runs.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

DIRECTIONS = 13
FIRST_DEG, STEP_DEG = -90.0, 15.0
NO_ECHO_CM = 255.0
FOV_RAD = math.radians(30.0)
MIN_RANGE_M, MAX_RANGE_M = 0.03, 2.55
STOP_PERIOD_NS = 1_000_000_000
FIRE_STEP_NS = 50_000_000
START_NS = 1_700_000_000 * 1_000_000_000
ECHO_RANGE_M = 1.5  # echoes scored: the EV3's cone is ~0.8 m wide at this range
RUNS = ("ev3-69", "ev3-101", "ev3-154", "ev3-222", "ev3")
REPO = Path(__file__).resolve().parents[1]
# The EV3 scale (laps of 6-10 m, walls ≤ 1.5 m away): submaps of 1 m of travel, matched within
# ±0.3 m and ±15°; loop closures among submaps within 1.5 m, searched ±0.5 m and ±20°.
CONFIG = """[pose_refinement]
max_echo_range_m = 1.5
submap_travel_m = 1.0
search_xy_m = 0.3
search_yaw_deg = 15.0
loop_radius_m = 1.5
loop_search_xy_m = 0.5
loop_search_yaw_deg = 20.0
calibration_far_range_m = 0.0
"""

F64 = npt.NDArray[np.float64]


class Ev3FormatError(ValueError):
    """A line of an EV3 log that is not ``x y theta`` and 13 blocks of readings."""


@dataclass(frozen=True)
class Stop:
    """One line of an EV3 log: the pose (m, m, rad as logged) and 13 ranges (m, +inf)."""

    x: float
    y: float
    theta: float
    ranges: tuple[float, ...]


def parse_line(text: str, where: str) -> Stop:
    """One log line → a :class:`Stop` (median per direction, cm → m)."""
    try:
        values = [float(v) for v in text.split()]
    except ValueError as exc:
        raise Ev3FormatError(f"{where}: not a number ({exc})") from None
    n = len(values) - 3
    if n < DIRECTIONS or n % DIRECTIONS:
        raise Ev3FormatError(
            f"{where}: {len(values)} fields, expected x y theta and 13 blocks of readings")
    k = n // DIRECTIONS
    blocks = np.asarray(values[3:]).reshape(DIRECTIONS, k)
    ranges = tuple(math.inf if m >= NO_ECHO_CM else m / 100.0
                   for m in (float(v) for v in np.median(blocks, axis=1)))
    return Stop(values[0] / 100.0, values[1] / 100.0, values[2], ranges)


def read_log(path: Path) -> list[Stop]:
    """Every non-blank line of an EV3 ``.log``."""
    lines = path.read_text(encoding="utf-8").splitlines()
    return [parse_line(s, f"{path}:{i}") for i, s in enumerate(lines, 1) if s.strip()]


def sensor_yaw(i: int) -> float:
    return math.radians(FIRST_DEG + STEP_DEG * i)


def stamp_ns(stop: int, direction: int) -> int:
    return START_NS + stop * STOP_PERIOD_NS + direction * FIRE_STEP_NS


def convert(stops: Sequence[Stop], out: Path) -> Path:
    """Write ``stops`` as a sonarmap CSV set (ranges.csv, poses.csv, sensors.csv) at ``out``
    (a new directory; formats.log_writers, the project's writer)."""
    from formats.contract import PoseBatch, SensorMount, make_range_batch
    from formats.log_writers import LogContent, write_log

    k, i = np.divmod(np.arange(len(stops) * DIRECTIONS), DIRECTIONS)
    ranges = make_range_batch(
        [stamp_ns(int(a), int(b)) for a, b in zip(k, i, strict=True)], i,
        [r for s in stops for r in s.ranges], FOV_RAD, MIN_RANGE_M, MAX_RANGE_M, scan_id=k)
    ends = np.arange(2 * len(stops))  # each stop's first and last firing
    at = ends // 2
    pose = np.array([[s.x, s.y, math.remainder(s.theta, math.tau)] for s in stops])[at]
    poses = PoseBatch(np.array([stamp_ns(int(a), (DIRECTIONS - 1) * int(e % 2))
                                for a, e in zip(at, ends, strict=True)], dtype=np.int64),
                      pose[:, 0].copy(), pose[:, 1].copy(), pose[:, 2].copy(),
                      "odom", "base_link")
    names = tuple(f"ev3_{d:02d}" for d in range(DIRECTIONS))
    mounts = {n: SensorMount(0.0, 0.0, sensor_yaw(d)) for d, n in enumerate(names)}
    return write_log(LogContent(ranges, names, poses, mounts), out, "csv-set")


def laps(stops: Sequence[Stop]) -> npt.NDArray[np.int64]:
    """Each stop's lap: whole turns of its logged (unwrapped) heading since the first stop."""
    theta = np.unwrap(np.array([s.theta for s in stops]))
    turns: npt.NDArray[np.int64] = np.floor(np.abs(theta - theta[0]) / math.tau).astype(np.int64)
    return turns


def echoes(stops: Sequence[Stop], poses: F64) -> tuple[F64, npt.NDArray[np.int64]]:
    """Echo points (n, 2) in the world under ``poses`` (stop, direction → x, y, yaw; shape
    (len(stops), 13, 3)) and each echo's stop index; echoes beyond ECHO_RANGE_M dropped."""
    r = np.array([s.ranges for s in stops])
    keep = np.isfinite(r) & (r <= ECHO_RANGE_M)
    r = np.where(keep, r, 0.0)
    bearing = poses[..., 2] + np.radians(FIRST_DEG + STEP_DEG * np.arange(DIRECTIONS))
    x = poses[..., 0] + r * np.cos(bearing)
    y = poses[..., 1] + r * np.sin(bearing)
    stop = np.broadcast_to(np.arange(len(stops))[:, None], r.shape)
    return np.column_stack([x[keep], y[keep]]), stop[keep]


def lap_spread(points: F64, lap: npt.NDArray[np.int64]) -> tuple[float, float]:
    """Median and 90th percentile (m) of each echo's distance to the nearest echo of another
    lap; NaN if fewer than two laps."""
    from scipy.spatial import cKDTree

    dist: list[F64] = []
    for k in np.unique(lap):
        mine, others = points[lap == k], points[lap != k]
        if len(mine) and len(others):
            dist.append(cKDTree(others).query(mine)[0])
    if not dist:
        return math.nan, math.nan
    d = np.concatenate(dist)
    return float(np.median(d)), float(np.percentile(d, 90))


def odometry_poses(stops: Sequence[Stop]) -> F64:
    """(stops, 13, 3): the logged pose at every reading (the rover stands while sweeping)."""
    p = np.array([[s.x, s.y, s.theta] for s in stops])
    return np.repeat(p[:, None, :], DIRECTIONS, axis=1)


def trajectory_poses(path: Path, n_stops: int) -> F64:
    """(stops, 13, 3): a run's ``trajectory.csv`` interpolated at every reading's stamp."""
    from formats.writers.trajectory_csv import read_trajectory

    tr = read_trajectory(path)
    t = np.asarray(tr.t_ns, dtype=np.int64)
    yaw = np.unwrap(np.asarray(tr.yaw, dtype=np.float64))
    q = np.array([[stamp_ns(k, i) for i in range(DIRECTIONS)] for k in range(n_stops)])
    rel = (q - t[0]).astype(np.float64)
    tt = (t - t[0]).astype(np.float64)
    return np.stack([np.interp(rel, tt, np.asarray(tr.x, dtype=np.float64)),
                     np.interp(rel, tt, np.asarray(tr.y, dtype=np.float64)),
                     np.interp(rel, tt, yaw)], axis=-1)


@dataclass(frozen=True)
class Row:
    """One run: its path length (m), laps, the spread (median, p90; m) under the odometry and
    under refinement, and refinement's own account (metrics.json ``pose_refinement``)."""

    name: str
    path_m: float
    laps: int
    raw: tuple[float, float]
    refined: tuple[float, float]
    refinement: dict[str, object]


def run_sonarmap(log: Path, out: Path, config: Path, refine: bool) -> dict[str, object]:
    """``sonarmap run`` (this interpreter's ``python -m cli``); its metrics.json."""
    cmd = [sys.executable, "-m", "cli", "run", str(log), "-o", str(out), "--config", str(config),
           "--quiet", "--force"] + (["--refine-poses"] if refine else [])
    subprocess.run(cmd, cwd=REPO, check=True, capture_output=True)
    metrics: dict[str, object] = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    return metrics


def path_length(stops: Sequence[Stop]) -> float:
    xy = np.array([[s.x, s.y] for s in stops])
    return float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))


def measure(name: str, stops: Sequence[Stop], work: Path, config: Path
            ) -> tuple[Row, F64, F64, npt.NDArray[np.int64]]:
    """Convert, run unrefined and refined, score both; the echoes for the figure too."""
    shutil.rmtree(work / name, ignore_errors=True)
    (work / name).mkdir(parents=True)
    log = convert(stops, work / name / "log")
    run_sonarmap(log, work / name / "raw", config, refine=False)
    metrics = run_sonarmap(log, work / name / "refined", config, refine=True)
    lap = laps(stops)
    raw_pts, stop = echoes(stops, odometry_poses(stops))
    ref_pts, _ = echoes(stops, trajectory_poses(work / name / "refined" / "trajectory.csv",
                                                len(stops)))
    pr = metrics.get("pose_refinement")
    row = Row(name, path_length(stops), int(lap.max()) + 1, lap_spread(raw_pts, lap[stop]),
              lap_spread(ref_pts, lap[stop]), pr if isinstance(pr, dict) else {})
    return row, raw_pts, ref_pts, lap[stop]


def what_refinement_did(pr: dict[str, object]) -> str:
    """What the calibration applied, the graph's verdict and counts, how far the poses moved
    (metrics.json ``pose_refinement``)."""
    if not pr:
        return "not run"

    def n(key: str) -> float:
        v = pr.get(key)
        return float(v) if isinstance(v, (int, float)) else 0.0

    scale, bias = n("search_scale_error"), n("search_heading_bias_deg_per_m")
    calibration = ", ".join([f"scale {100 * scale:+.1f} %"] * bool(scale)
                            + [f"bias {bias:+.2f}°/m"] * bool(bias)) or "nothing"
    verdict = "applied" if pr.get("accepted") else "declined"
    return (f"calibration: {calibration}; graph {verdict}: {n('submaps'):.0f} submaps, {n('matches_accepted'):.0f} of "
            f"{n('matches_accepted') + n('matches_rejected'):.0f} matches, "
            f"{n('loop_closures_accepted'):.0f} of {n('loop_closures_tried'):.0f} closures; "
            f"moved {n('moved_max_m'):.2f} m max")


def _spread(s: tuple[float, float]) -> str:
    return "— (one lap)" if math.isnan(s[0]) else f"{s[0]:.3f} / {s[1]:.3f} m"


def markdown(rows: Sequence[Row]) -> str:
    lines = ["| run (path, laps) | odometry: median / p90 | refined: median / p90 | refinement |",
             "|---|---|---|---|"]
    lines += [f"| {r.name} ({r.path_m:.0f} m, {r.laps}) | {_spread(r.raw)} | {_spread(r.refined)} "
              f"| {what_refinement_did(r.refinement)} |" for r in rows]
    return "\n".join(lines)


LAP_RGB = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
           (140, 86, 75))
PANEL_PX = 320


def figure(panels: Sequence[tuple[Row, F64, F64, npt.NDArray[np.int64]]], path: Path) -> None:
    """Each run's echoes coloured by lap, under the odometry (left) and refined (right), one
    row per run, both panels of a row at the same scale."""
    from PIL import Image, ImageDraw

    rows = []
    for row, raw, ref, lap in panels:
        both = np.vstack([raw, ref])
        lo, span = both.min(axis=0), float(np.ptp(both, axis=0).max()) or 1.0
        canvas = Image.new("RGB", (2 * PANEL_PX, PANEL_PX + 16), "white")
        draw = ImageDraw.Draw(canvas)
        for col, (pts, label, spread) in enumerate(((raw, "odometry", row.raw),
                                                    (ref, "refined", row.refined))):
            draw.text((col * PANEL_PX + 4, 2), f"{row.name} {label}: lap spread "
                      f"{_spread(spread).replace('—', 'n/a')}", fill="black")
            px = (pts - lo) / span * (PANEL_PX - 12) + 6
            for (x, y), k in zip(px, lap, strict=True):
                u, v = col * PANEL_PX + x, 16 + PANEL_PX - y
                draw.rectangle((u - 1, v - 1, u + 1, v + 1), fill=LAP_RGB[int(k) % len(LAP_RGB)])
        draw.line((PANEL_PX, 0, PANEL_PX, PANEL_PX + 16), fill="grey")
        rows.append(canvas)
    full = Image.new("RGB", (2 * PANEL_PX, sum(r.height for r in rows)), "white")
    for i, r in enumerate(rows):
        full.paste(r, (0, i * (PANEL_PX + 16)))
    full.quantize(colors=64, dither=Image.Dither.NONE).save(path, format="PNG", optimize=True)


def log_dir(source: Path) -> Path:
    """The directory of the EV3 logs: ``source`` itself or its sparse-gslam subdirectory."""
    for d in (source, source / "src" / "sparse_gslam" / "datasets" / "ev3"):
        if any(d.glob("ev3*.log")):
            return d
    raise FileNotFoundError(f"{source}: no ev3*.log here nor in src/sparse_gslam/datasets/ev3 "
                            "(git clone https://github.com/sg2295/sparse-gslam)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("source", type=Path, help="sparse-gslam checkout or its ev3 directory")
    parser.add_argument("--runs", nargs="+", default=list(RUNS), help="log names (no .log)")
    parser.add_argument("--work", type=Path, help="keep the CSV sets and runs here")
    parser.add_argument("--figure", type=Path, help="PNG of the echoes, odometry | refined")
    parser.add_argument("--config", type=Path, help="TOML for both runs (default: CONFIG)")
    args = parser.parse_args(argv)
    try:
        source = log_dir(args.source)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    work = args.work or Path(tempfile.mkdtemp(prefix="sonarmap-ev3-laps-"))
    work.mkdir(parents=True, exist_ok=True)
    config = args.config
    if config is None:
        config = work / "ev3.toml"
        config.write_text(CONFIG, encoding="utf-8")
    panels = []
    for name in args.runs:
        path = source / f"{name}.log"
        if not path.is_file():
            print(f"{name}: no {path}, skipped", file=sys.stderr)
            continue
        panels.append(measure(name, read_log(path), work, config))
        print(f"{name}: {what_refinement_did(panels[-1][0].refinement)}", file=sys.stderr)
    print(markdown([p[0] for p in panels]))
    if args.figure and panels:
        figure(panels, args.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
