"""CsvLogReader: both layouts, every option, exact values."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from csvlog_helpers import make_config, read_all, write

import formats.csv_log as csv_log
from formats import detect_format, open_log
from formats.contract import LogReader, PoseBatch, RangeBatch
from formats.csv_log import CsvLogReader, looks_like_csv

MOUNTS = {
    "mounts": [
        {"name": "front", "yaw_deg": 0.0, "fov_deg": 30.0, "min_range": 0.1, "max_range": 4.0},
        {"name": "left", "yaw_deg": 90.0},
    ],
    "fov_deg": 20.0,
    "max_range": 6.0,
}

SINGLE = """t,x,y,yaw,sensor,range
1.5,0.0,0.0,0.0,front,1.25
1.5,0.0,0.0,0.0,left,inf
1.75,0.5,0.25,0.125,front,-inf
1.75,0.5,0.25,0.125,left,nan
2.0,1.0,0.5,0.25,front,3.5
"""


def test_single_layout_values_and_ids(tmp_path: Path) -> None:
    path = write(tmp_path, "log.csv", SINGLE)
    r, p, mounts, names = read_all(path, make_config(sensors=MOUNTS))
    assert names == ["front", "left"]
    assert r.t_ns.tolist() == [1_500_000_000] * 2 + [1_750_000_000] * 2 + [2_000_000_000]
    assert r.sensor_id.tolist() == [0, 1, 0, 1, 0]
    assert r.range_m[[0, 4]].tolist() == [1.25, 3.5]
    assert r.range_m[1] == np.inf and r.range_m[2] == -np.inf and np.isnan(r.range_m[3])
    # front: its own mount entry; left: [sensors] defaults for fov/max, nothing for min.
    assert r.fov_rad.tolist() == pytest.approx(
        [math.radians(30), math.radians(20)] * 2 + [math.radians(30)]
    )
    assert r.min_range_m[0] == 0.1 and np.isnan(r.min_range_m[1])
    assert r.max_range_m.tolist() == [4.0, 6.0, 4.0, 6.0, 4.0]
    assert r.scan_id.tolist() == [-1] * 5
    assert r.record_t_ns.tolist() == r.t_ns.tolist()
    assert np.isnan(r.variance).all()
    assert r.t_ns.dtype == np.int64 and r.sensor_id.dtype == np.int32
    # Poses: the distinct (t, x, y, yaw) rows, in file order.
    assert p is not None
    assert p.t_ns.tolist() == [1_500_000_000, 1_750_000_000, 2_000_000_000]
    assert p.x.tolist() == [0.0, 0.5, 1.0] and p.y.tolist() == [0.0, 0.25, 0.5]
    assert p.yaw.tolist() == [0.0, 0.125, 0.25]
    assert (p.parent_frame, p.child_frame) == ("odom", "base_link")
    assert mounts == {}


def test_reader_satisfies_contract_and_kinds_filter(tmp_path: Path) -> None:
    path = write(tmp_path, "log.csv", SINGLE)
    with CsvLogReader(path, make_config()) as reader:
        assert isinstance(reader, LogReader)
        assert reader.format_name == "csv" and reader.path == path
        only_poses = list(reader.batches(["poses"]))
        only_ranges = list(reader.batches(["ranges"]))
    assert [type(b) for b in only_poses] == [PoseBatch]
    assert [type(b) for b in only_ranges] == [RangeBatch]
    assert len(only_ranges[0]) == 5


def test_columns_any_order_case_insensitive_unknown_ignored(tmp_path: Path) -> None:
    text = "Range,SENSOR,extra,Yaw,T,y,X\n2.5,s1,zzz,0.5,10,2,1\n"
    r, p, _, names = read_all(write(tmp_path, "log.csv", text), make_config())
    assert names == ["s1"]
    assert r.range_m.tolist() == [2.5] and r.t_ns.tolist() == [10_000_000_000]
    assert p is not None and (p.x[0], p.y[0], p.yaw[0]) == (1.0, 2.0, 0.5)


def test_optional_columns_override_config_and_empty_falls_back(tmp_path: Path) -> None:
    text = (
        "t,x,y,yaw,sensor,range,fov,min_range,max_range,scan\n"
        "0,0,0,0,front,100,10,5,300,7\n"
        "0,0,0,0,front,200,,,,\n"
    )
    cfg = make_config({"length_unit": "cm", "angle_unit": "deg"}, MOUNTS)
    r, _, _, _ = read_all(write(tmp_path, "log.csv", text), cfg)
    assert r.range_m.tolist() == [1.0, 2.0]
    assert r.fov_rad.tolist() == pytest.approx([math.radians(10), math.radians(30)])
    assert r.min_range_m.tolist() == [0.05, 0.1]
    assert r.max_range_m.tolist() == [3.0, 4.0]
    assert r.scan_id.tolist() == [7, -1]


@pytest.mark.parametrize(
    ("literal", "expected"),
    [("inf", np.inf), ("+inf", np.inf), ("Infinity", np.inf), ("-inf", -np.inf), ("-Inf", -np.inf)],
)
def test_rep117_infinity_literals(tmp_path: Path, literal: str, expected: float) -> None:
    text = f"t,x,y,yaw,sensor,range\n0,0,0,0,s,{literal}\n"
    r, _, _, _ = read_all(write(tmp_path, "log.csv", text), make_config())
    assert r.range_m[0] == expected


def test_rep117_nan_literals(tmp_path: Path) -> None:
    text = "t,x,y,yaw,sensor,range\n0,0,0,0,s,nan\n0,0,0,0,s,NaN\n"
    r, _, _, _ = read_all(write(tmp_path, "log.csv", text), make_config())
    assert np.isnan(r.range_m).tolist() == [True, True]


@pytest.mark.parametrize(
    ("unit", "text", "ns"),
    [
        ("s", "1700000000.123456789", 1_700_000_000_123_456_789),
        ("s", "1700000000", 1_700_000_000_000_000_000),
        ("s", ".5", 500_000_000),
        ("s", "-1.25", -1_250_000_000),
        ("s", "+2.000000001", 2_000_000_001),
        ("s", "0.0000000015", 2),  # below 1 ns: rounded half away from zero
        ("s", "0.0000000014999", 1),
        ("s", "1.5e3", 1_500_000_000_000),  # exponent notation goes the Decimal way
        ("ms", "1686487", 1_686_487_000_000),
        ("ms", "1686487.5", 1_686_487_500_000),
        ("ms", "0.000001", 1),
        ("us", "1234567.891", 1_234_567_891),
        ("ns", "1700000000123456789", 1_700_000_000_123_456_789),
        ("ns", "12.5", 13),
        ("s", "9223372036.854775807", 2**63 - 1),  # past the fast path's limit, still exact
        ("s", "0001.5", 1_500_000_000),
        ("ns", "-9223372036854775808", -(2**63)),
    ],
)
def test_time_units_exact_to_the_ns(tmp_path: Path, unit: str, text: str, ns: int) -> None:
    path = write(tmp_path, "log.csv", f"t,x,y,yaw,sensor,range\n{text},0,0,0,s,1\n")
    r, p, _, _ = read_all(path, make_config({"time_unit": unit}))
    assert r.t_ns.tolist() == [ns]
    assert p is not None and p.t_ns.tolist() == [ns]


def test_time_parsing_is_exact_where_float_is_not(tmp_path: Path) -> None:
    # float("1700000000.000000001") * 1e9 loses the last digit; the decimal parse keeps it.
    rows = "".join(f"1700000000.{i:09d},0,0,0,s,1\n" for i in range(1, 200, 7))
    r, _, _, _ = read_all(
        write(tmp_path, "log.csv", "t,x,y,yaw,sensor,range\n" + rows), make_config()
    )
    assert r.t_ns.tolist() == [1_700_000_000_000_000_000 + i for i in range(1, 200, 7)]


@pytest.mark.parametrize(
    ("unit", "raw", "metres"),
    [("m", "2.32", 2.32), ("cm", "232", 2.32), ("mm", "2320", 2.32), ("mm", "170", 0.17)],
)
def test_length_units(tmp_path: Path, unit: str, raw: str, metres: float) -> None:
    text = f"t,x,y,yaw,sensor,range,min_range\n0,{raw},-{raw},0,s,{raw},{raw}\n"
    r, p, _, _ = read_all(write(tmp_path, "log.csv", text), make_config({"length_unit": unit}))
    # Exact: the unit is divided out, so 2320 mm is the double nearest to 2.32.
    assert r.range_m[0] == metres and r.min_range_m[0] == metres
    assert p is not None and p.x[0] == metres and p.y[0] == -metres


@pytest.mark.parametrize(
    ("unit", "raw", "rad"),
    [
        ("rad", "1.5", 1.5),
        ("deg", "90", math.pi / 2),
        ("deg", "-45", -math.pi / 4),
        ("tenths", "900", math.pi / 2),
        ("tenths", "2631", math.radians(263.1)),
    ],
)
def test_angle_units(tmp_path: Path, unit: str, raw: str, rad: float) -> None:
    text = f"t,x,y,yaw,sensor,range,fov\n0,0,0,{raw},s,1,{raw}\n"
    r, p, _, _ = read_all(write(tmp_path, "log.csv", text), make_config({"angle_unit": unit}))
    assert p is not None and p.yaw[0] == pytest.approx(rad, rel=1e-15)
    assert r.fov_rad[0] == pytest.approx(rad, rel=1e-15)


def test_whitespace_delimiter_runs_of_blanks_and_tabs(tmp_path: Path) -> None:
    text = "t x   y\tyaw sensor range\n  1  2 \t 3  0.5   s0   4.5  \n"
    r, p, _, names = read_all(
        write(tmp_path, "log.txt", text), make_config({"delimiter": "whitespace"})
    )
    assert names == ["s0"] and r.range_m.tolist() == [4.5]
    assert p is not None and (p.t_ns[0], p.x[0], p.y[0], p.yaw[0]) == (1_000_000_000, 2.0, 3.0, 0.5)


def test_semicolon_and_multichar_delimiters(tmp_path: Path) -> None:
    semi = write(tmp_path, "a.csv", "t;x;y;yaw;sensor;range\n1;2;3;0;s;4\n")
    r, _, _, _ = read_all(semi, make_config({"delimiter": ";"}))
    assert r.range_m.tolist() == [4.0]
    multi = write(tmp_path, "b.csv", "t::x::y::yaw::sensor::range\n1::2::3::0::s::5\n")
    r, _, _, _ = read_all(multi, make_config({"delimiter": "::"}))
    assert r.range_m.tolist() == [5.0]


def test_quoted_sensor_name_with_delimiter(tmp_path: Path) -> None:
    text = 't,x,y,yaw,sensor,range\n0,0,0,0,"ring, front",1.5\n0, 0, 0, 0, plain , 2\n'
    r, _, _, names = read_all(write(tmp_path, "log.csv", text), make_config())
    assert names == ["ring, front", "plain"]
    assert r.range_m.tolist() == [1.5, 2.0]


def test_no_header_positional_columns(tmp_path: Path) -> None:
    six = write(tmp_path, "six.csv", "1,2,3,0.5,s,4\n")
    r, p, _, _ = read_all(six, make_config({"header": False}))
    assert r.range_m.tolist() == [4.0] and r.scan_id.tolist() == [-1]
    assert p is not None and p.x.tolist() == [2.0]
    ten = write(tmp_path, "ten.csv", "1,2,3,0.5,s,4,0.25,0.5,3.5,12\n")
    r, _, _, _ = read_all(ten, make_config({"header": False}))
    assert (r.fov_rad[0], r.min_range_m[0], r.max_range_m[0], r.scan_id[0]) == (0.25, 0.5, 3.5, 12)


def test_comments_and_blank_lines_are_ignored(tmp_path: Path) -> None:
    text = "# a log\n\nt,x,y,yaw,sensor,range\n  # another comment\n\n1,0,0,0,s#1,2\n\n# end\n"
    r, _, _, names = read_all(write(tmp_path, "log.csv", text), make_config())
    assert r.range_m.tolist() == [2.0] and names == ["s#1"]  # only a leading '#' comments


@pytest.mark.parametrize(
    "tail",
    ["1,0,0,0,s,3", "1,0,0,0,s,3\r\n", "1,0,0,0,s,3\n   \t\n", "1,0,0,0,s,3\n  "],
)
def test_whitespace_only_lines_and_missing_final_newline(tmp_path: Path, tail: str) -> None:
    text = "t,x,y,yaw,sensor,range\r\n1,0,0,0,s,2\r\n \t \r\n" + tail
    r, _, _, _ = read_all(write(tmp_path, "log.csv", text), make_config())
    assert r.range_m.tolist() == [2.0, 3.0]


def test_no_echo_value_becomes_pos_inf(tmp_path: Path) -> None:
    text = "t,x,y,yaw,sensor,range\n0,0,0,0,s,5110\n0,0,0,0,s,5109\n0,0,0,0,s,-1\n"
    path = write(tmp_path, "log.csv", text)
    r, _, _, _ = read_all(path, make_config({"length_unit": "mm", "no_echo_value": 5110.0}))
    assert r.range_m.tolist() == [np.inf, 5.109, -0.001]
    # The default (negative) means none: values stay as they are.
    r, _, _, _ = read_all(path, make_config({"length_unit": "mm"}))
    assert r.range_m.tolist() == [5.11, 5.109, -0.001]


def test_unsorted_time_is_kept_in_file_order(tmp_path: Path) -> None:
    text = "t,x,y,yaw,sensor,range\n3,0,0,0,s,1\n1,0,0,0,s,2\n2,0,0,0,s,3\n"
    r, p, _, _ = read_all(write(tmp_path, "log.csv", text), make_config())
    assert r.t_ns.tolist() == [3_000_000_000, 1_000_000_000, 2_000_000_000]
    assert p is not None and p.t_ns.tolist() == r.t_ns.tolist()


def test_chunking_keeps_ids_scans_and_pose_dedup(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(csv_log, "CHUNK_BYTES", 40)
    rows = "".join(f"{i // 2},{i // 2},0,0,{'ab'[i % 2]},{i},,,,{i // 4}\n" for i in range(10))
    path = write(
        tmp_path, "log.csv", "t,x,y,yaw,sensor,range,fov,min_range,max_range,scan\n" + rows
    )
    with CsvLogReader(path, make_config()) as reader:
        batches = list(reader.batches())
    assert sum(isinstance(b, RangeBatch) for b in batches) >= 3
    r = RangeBatch.concat([b for b in batches if isinstance(b, RangeBatch)])
    assert r.sensor_id.tolist() == [0, 1] * 5
    assert r.range_m.tolist() == [float(i) for i in range(10)]
    assert r.scan_id.tolist() == [i // 4 for i in range(10)]
    poses = [b for b in batches if isinstance(b, PoseBatch)]
    t = np.concatenate([b.t_ns for b in poses])
    # A pose repeated across a chunk boundary is yielded once.
    assert t.tolist() == [i * 1_000_000_000 for i in range(5)]


SENSORS_CSV = (
    "sensor,x,y,yaw,fov,min_range,max_range\nfront,0.2,0,0,0.5,0.05,2.5\nleft,0,0.1,1.5,,,\n"
)


def test_set_layout_long_ranges_with_sensors_file(tmp_path: Path) -> None:
    write(
        tmp_path, "ranges.csv", "t,sensor,range,scan\n1,front,1.0,0\n1,left,2.0,0\n2,back,inf,1\n"
    )
    write(tmp_path, "poses.csv", "t,x,y,yaw\n0.5,0,0,0\n2.5,1,0,0\n")
    write(tmp_path, "sensors.csv", SENSORS_CSV)
    r, p, mounts, names = read_all(tmp_path, make_config({"layout": "set"}, MOUNTS))
    assert names == ["front", "left", "back"]
    assert r.range_m.tolist() == [1.0, 2.0, np.inf] and r.scan_id.tolist() == [0, 0, 1]
    assert p is not None and p.t_ns.tolist() == [500_000_000, 2_500_000_000]
    assert set(mounts) == {"front", "left"}
    assert (mounts["front"].x, mounts["left"].y, mounts["left"].yaw) == (0.2, 0.1, 1.5)
    # sensors.csv limits come before the config; empty fields fall back to the config.
    assert r.fov_rad.tolist() == pytest.approx([0.5, math.radians(20), math.radians(20)])
    assert r.max_range_m.tolist() == [2.5, 6.0, 6.0]
    assert r.min_range_m[0] == 0.05 and np.isnan(r.min_range_m[1:]).all()


def test_set_layout_path_may_name_one_of_its_files(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "t,sensor,range\n1,s,1.0\n")
    write(tmp_path, "poses.csv", "t,x,y,yaw\n1,0,0,0\n")
    r, p, mounts, _ = read_all(tmp_path / "poses.csv", make_config({"layout": "set"}))
    assert r.range_m.tolist() == [1.0] and p is not None and len(p) == 1
    assert mounts == {}  # no sensors.csv: no MountBatch


def test_set_layout_order_mounts_poses_ranges(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "t,sensor,range\n1,front,1.0\n")
    write(tmp_path, "poses.csv", "t,x,y,yaw\n1,0,0,0\n")
    write(tmp_path, "sensors.csv", SENSORS_CSV)
    with CsvLogReader(tmp_path, make_config({"layout": "set"})) as reader:
        kinds = [type(b).__name__ for b in reader.batches()]
    assert kinds == ["MountBatch", "PoseBatch", "RangeBatch"]


def test_wide_ranges_with_header(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(csv_log, "CHUNK_BYTES", 40)
    write(tmp_path, "r.csv", "t,Left,right\n1,1.0,2.0\n2,3.0,inf\n3,5.0,6.0\n")
    write(tmp_path, "p.csv", "t,x,y,yaw\n1,0,0,0\n")
    cfg = make_config(
        {"layout": "set", "wide_ranges": True, "ranges_file": "r.csv", "poses_file": "p.csv"}
    )
    r, _, _, names = read_all(tmp_path, cfg)
    assert names == ["Left", "right"]  # sensor names keep their case
    assert r.t_ns.tolist() == [1_000_000_000] * 2 + [2_000_000_000] * 2 + [3_000_000_000] * 2
    assert r.sensor_id.tolist() == [0, 1, 0, 1, 0, 1]
    assert r.range_m.tolist() == [1.0, 2.0, 3.0, np.inf, 5.0, 6.0]
    assert r.scan_id.tolist() == [0, 0, 1, 1, 2, 2]  # a row is a scan, across chunks


def test_wide_ranges_without_header_names_sonar_i(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "10 1 2 3\n20 4 5 6\n")
    write(tmp_path, "poses.csv", "10 0 0 0\n")
    cfg = make_config(
        {"layout": "set", "wide_ranges": True, "header": False, "delimiter": "whitespace"}
    )
    r, _, _, names = read_all(tmp_path, cfg)
    assert names == ["sonar_0", "sonar_1", "sonar_2"]
    assert r.range_m.tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]


def test_info_single_layout(tmp_path: Path) -> None:
    path = write(tmp_path, "log.csv", "# c\n" + SINGLE)
    with CsvLogReader(path, make_config()) as reader:
        info = reader.info()
    assert info.format == "csv"
    assert (info.start_ns, info.end_ns) == (1_500_000_000, 2_000_000_000)
    assert [(t.name, t.msgtype, t.count) for t in info.topics] == [
        ("log.csv", "csv/ranges", 5),
        ("log.csv", "csv/poses", 3),
    ]
    assert info.message_count == 5
    assert "sensors: front, left" in info.notes


def test_info_set_layout(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "t,a,b\n1,1,1\n2,1,1\n3,1,1\n")
    write(tmp_path, "poses.csv", "t,x,y,yaw\n0,0,0,0\n4,0,0,0\n")
    write(tmp_path, "sensors.csv", "sensor,x,y,yaw\na,0,0,0\nb,0,0,1\n")
    with CsvLogReader(tmp_path, make_config({"layout": "set", "wide_ranges": True})) as reader:
        info = reader.info()
    assert [(t.name, t.msgtype, t.count, t.role) for t in info.topics] == [
        ("ranges.csv", "csv/ranges", 3, "range"),
        ("poses.csv", "csv/poses", 2, "pose"),
        ("sensors.csv", "csv/sensors", 2, "tf_static"),
    ]
    assert (info.start_ns, info.end_ns, info.message_count) == (0, 4_000_000_000, 7)
    assert info.notes[0] == "6 range readings from 2 sensors"


def test_reading_twice_is_identical(tmp_path: Path) -> None:
    path = write(tmp_path, "log.csv", SINGLE)
    cfg = make_config(sensors=MOUNTS)
    a, _, _, _ = read_all(path, cfg)
    b, _, _, _ = read_all(path, cfg)
    for f in ("t_ns", "sensor_id", "range_m", "fov_rad", "min_range_m", "max_range_m", "scan_id"):
        assert getattr(a, f).tobytes() == getattr(b, f).tobytes()


def test_looks_like_csv(tmp_path: Path) -> None:
    assert looks_like_csv(write(tmp_path, "a.csv", "# x\nt,x,y\n"))
    assert looks_like_csv(write(tmp_path, "b.txt", "1686487 5110 5110\n"))
    assert not looks_like_csv(write(tmp_path, "c.txt", "justoneword\n"))
    assert not looks_like_csv(write(tmp_path, "d.csv", ""))
    assert not looks_like_csv(write(tmp_path, "e.csv", "# only a comment\n"))
    (tmp_path / "f.bag").write_bytes(b"#ROSBAG V2.0\n\x00\x01\x02 binary")
    assert not looks_like_csv(tmp_path / "f.bag")
    (tmp_path / "g.bin").write_bytes(b"\xff\xfe,\xfa,\n")
    assert not looks_like_csv(tmp_path / "g.bin")
    assert not looks_like_csv(tmp_path / "missing.csv")
    folder = tmp_path / "set"
    folder.mkdir()
    assert not looks_like_csv(folder)
    write(folder, "measurement.txt", "1 2\n")
    write(folder, "poses.txt", "1 2 3 4\n")
    cfg = make_config({"ranges_file": "measurement.txt", "poses_file": "poses.txt"})
    assert not looks_like_csv(folder) and looks_like_csv(folder, cfg)
    write(folder, "ranges.csv", "t,s,r\n")
    write(folder, "poses.csv", "t,x,y,yaw\n")
    assert looks_like_csv(folder)


def test_detected_and_opened_through_open_log(tmp_path: Path) -> None:
    path = write(tmp_path, "log.csv", SINGLE)
    assert detect_format(path) == "csv"
    with open_log(path, make_config()) as reader:
        assert isinstance(reader, CsvLogReader)
        assert reader.info().topics[0].count == 5


def test_writer_convention_round_trips_exactly(tmp_path: Path) -> None:
    """Rows written the way the CSV log writer does (t as <sec>.<9-digit ns>, repr floats)."""
    rng = np.random.default_rng(7)
    t = np.sort(rng.integers(1_600_000_000_000_000_000, 1_800_000_000_000_000_000, 500))
    vals = rng.normal(0.0, 3.0, (500, 4))
    lines = ["t,x,y,yaw,sensor,range"] + [
        f"{ns // 10**9}.{ns % 10**9:09d},{x!r},{y!r},{a!r},s{i % 3},{abs(d)!r}"
        for i, (ns, (x, y, a, d)) in enumerate(zip(t.tolist(), vals.tolist(), strict=True))
    ]
    path = write(tmp_path, "log.csv", "\n".join(lines) + "\n")
    r, p, _, names = read_all(path, make_config())
    assert names == ["s0", "s1", "s2"]
    assert r.t_ns.tolist() == t.tolist()
    assert r.range_m.tolist() == np.abs(vals[:, 3]).tolist()
    assert (
        p is not None
        and p.x.tolist() == vals[:, 0].tolist()
        and p.yaw.tolist() == vals[:, 2].tolist()
    )
