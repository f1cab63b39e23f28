"""benchmarks.ev3_laps: the EV3 log converter (values, stamps, sensor angles) and the lap
spread, on synthetic lines (no sparse-gslam checkout needed)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.ev3_laps import (
    DIRECTIONS,
    LAP_RGB,
    PANEL_PX,
    Ev3FormatError,
    Row,
    Stop,
    convert,
    echoes,
    figure,
    lap_spread,
    laps,
    main,
    markdown,
    odometry_poses,
    parse_line,
    read_log,
)
from formats import open_log
from formats.contract import MountBatch, PoseBatch, RangeBatch
from pipeline.config import Config


def _line(x: float, y: float, theta: float, blocks: list[list[float]]) -> str:
    return " ".join(str(v) for v in [x, y, theta, *(r for b in blocks for r in b)])


# Direction i reads (40 + i, 42 + i, 300) cm: median 42 + i; direction 12 never echoes.
BLOCKS = [[40.0 + i, 300.0, 42.0 + i] for i in range(DIRECTIONS - 1)] + [[255.0, 255.0, 80.0]]


def test_a_line_is_a_pose_in_metres_and_the_median_of_each_direction() -> None:
    stop = parse_line(_line(150.0, -20.0, -7.0, BLOCKS), "run.log:1")
    assert (stop.x, stop.y, stop.theta) == (1.5, -0.2, -7.0)
    assert stop.ranges[:3] == (0.42, 0.43, 0.44)
    assert stop.ranges[11] == 0.53
    assert stop.ranges[12] == math.inf
    one = parse_line(_line(0, 0, 0, [[10.0 * (i + 1)] for i in range(DIRECTIONS)]), "x")
    assert one.ranges[0] == 0.1 and one.ranges[12] == 1.3


@pytest.mark.parametrize("text", ["1 2 3 4 5", "0 0 0 " + " ".join(["1"] * 27), "0 0 x 1"])
def test_a_malformed_line_names_its_file_and_line(tmp_path: Path, text: str) -> None:
    log = tmp_path / "ev3-1.log"
    log.write_text(_line(0, 0, 0, BLOCKS) + "\n\n" + text + "\n")
    with pytest.raises(Ev3FormatError, match=r"ev3-1.log:3: "):
        read_log(log)


def test_the_csv_set_reads_back_with_synthesised_stamps_and_13_directions(tmp_path: Path) -> None:
    stops = [parse_line(_line(0, 0, 0, BLOCKS), "a"), parse_line(_line(20, 0, 7.0, BLOCKS), "b")]
    out = convert(stops, tmp_path / "set")
    with open_log(out, Config()) as reader:
        batches = list(reader.batches())
        names = list(reader.sensor_names)
    (mounts,) = [b.mounts for b in batches if isinstance(b, MountBatch)]
    assert [round(math.degrees(mounts[f"ev3_{i:02d}"].yaw)) for i in range(13)] == list(
        range(-90, 91, 15))
    r = RangeBatch.concat([b for b in batches if isinstance(b, RangeBatch)])
    t0 = 1_700_000_000 * 10**9
    assert r.t_ns.tolist() == [t0 + k * 10**9 + i * 50_000_000 for k in (0, 1) for i in range(13)]
    assert [names[s] for s in r.sensor_id[:2]] == ["ev3_00", "ev3_01"]
    assert r.range_m[:2].tolist() == [0.42, 0.43] and math.isinf(r.range_m[12])
    assert np.allclose(r.fov_rad, math.radians(30)) and np.all(r.max_range_m == 2.55)
    p = PoseBatch  # the rover stands while it sweeps: a pose at the first and last firing
    (poses,) = [b for b in batches if isinstance(b, p)]
    assert poses.t_ns.tolist() == [t0, t0 + 600_000_000, t0 + 10**9, t0 + 1_600_000_000]
    assert poses.x.tolist() == [0.0, 0.0, 0.2, 0.2]
    assert poses.yaw[2] == pytest.approx(7.0 - 2 * math.pi)  # wrapped to (−π, π]


def _square_lap(offset: float) -> list[Stop]:
    """A 2 m square walked anticlockwise in 8 stops (a quarter turn at each corner), the
    straight-ahead direction reading 0.5 m, the others nothing; ``offset`` shifts the lap's
    poses in x."""
    ahead = tuple(0.5 if i == 6 else math.inf for i in range(DIRECTIONS))
    corners = [(0, 0), (1, 0), (2, 0), (2, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    headings = [0, 0, math.pi / 2, math.pi / 2, math.pi, math.pi, 1.5 * math.pi, 1.5 * math.pi]
    return [Stop(x + offset, float(y), h, ahead)
            for (x, y), h in zip(corners, headings, strict=True)]


def test_laps_split_by_whole_turns_and_the_spread_measures_their_offset() -> None:
    one, two = _square_lap(0.0), _square_lap(0.1)
    stops = one + [Stop(s.x, s.y, s.theta + 2 * math.pi, s.ranges) for s in two]
    lap = laps(stops)
    assert lap.tolist() == [0] * 8 + [1] * 8
    pts, stop = echoes(stops, odometry_poses(stops))
    assert len(pts) == 16
    assert pts[2].tolist() == [2.0, 0.5]
    median, p90 = lap_spread(pts, lap[stop])
    assert median == pytest.approx(0.1) and p90 == pytest.approx(0.1)
    same = one + [Stop(s.x, s.y, s.theta + 2 * math.pi, s.ranges) for s in one]
    pts, stop = echoes(same, odometry_poses(same))
    assert lap_spread(pts, laps(same)[stop]) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert all(math.isnan(v) for v in lap_spread(pts, np.zeros(len(pts), dtype=np.int64)))


def test_without_the_logs_the_benchmark_says_where_to_get_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(tmp_path)]) == 1
    assert "git clone https://github.com/sg2295/sparse-gslam" in capsys.readouterr().err


def test_the_table_row_says_what_refinement_did() -> None:
    pr = {"accepted": False, "submaps": 10, "matches_accepted": 1, "matches_rejected": 9,
          "loop_closures_tried": 7, "loop_closures_accepted": 2, "moved_max_m": 0.5,
          "search_scale_error": 0.0, "search_heading_bias_deg_per_m": -2.8125}
    rows = [Row("ev3-69", 10.4, 3, (0.05, 0.164), (0.05, 0.164), pr),
            Row("ev3-101", 14.6, 1, (math.nan, math.nan), (math.nan, math.nan), {})]
    table = markdown(rows).splitlines()
    assert table[2] == ("| ev3-69 (10 m, 3) | 0.050 / 0.164 m | 0.050 / 0.164 m | calibration: bias "
                        "-2.81°/m; graph declined: 10 submaps, 1 of 10 matches, 2 of 7 closures; "
                        "moved 0.50 m max |")
    assert table[3] == "| ev3-101 (15 m, 1) | — (one lap) | — (one lap) | not run |"


def test_the_figure_has_a_row_of_two_panels_per_run(tmp_path: Path) -> None:
    from PIL import Image

    pts = np.array([[0.0, 0.0], [1.0, 2.0]])
    row = Row("a", 1.0, 2, (0.1, 0.2), (0.05, 0.1), {})
    figure([(row, pts, pts + 0.1, np.array([0, 1]))] * 2, tmp_path / "f.png")
    with Image.open(tmp_path / "f.png") as img:
        assert img.size == (2 * PANEL_PX, 2 * (PANEL_PX + 16))
        rgb = img.convert("RGB")
        # the first echo (lap 0) at the lower left of the left panel, blue
        assert rgb.getpixel((6, 16 + PANEL_PX - 6)) == LAP_RGB[0]
