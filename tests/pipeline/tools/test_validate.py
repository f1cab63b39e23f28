"""validate_log: small CSV logs with one planted problem each."""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import formats.csv_log as csv_log
from formats.contract import ALL_KINDS, Batch, Kind, LogInfo, PoseBatch, make_range_batch
from formats.csv_log import CsvLogReader
from pipeline.config import Config, config_from_dict, load_config
from pipeline.stages.ingest import StampOrder
from pipeline.tools.validate import Finding, ValidationReport, validate_log

SENSORS = {
    "mounts": [
        {"name": "s0", "yaw_deg": 0.0, "fov_deg": 30.0, "min_range": 0.1, "max_range": 5.0},
        {"name": "s1", "yaw_deg": 90.0, "fov_deg": 30.0, "min_range": 0.1, "max_range": 5.0},
    ]
}
SAMPLE = Path(__file__).resolve().parents[3] / "sample_logs" / "udacity-8sonar"


def _config(csv: dict[str, Any] | None = None, **sections: Any) -> Config:
    data: dict[str, Any] = {"input": {"csv": csv or {}}, "sensors": SENSORS, **sections}
    return config_from_dict(data)


def _rows(n: int = 20, dt: float = 0.1, t0: float = 0.0) -> list[tuple[float, str, str]]:
    """Readings alternating s0/s1, changing ranges, every dt seconds."""
    return [(t0 + i * dt, f"s{i % 2}", f"{1.0 + 0.01 * i:.2f}") for i in range(n)]


def _write_set(
    folder: Path,
    ranges: Sequence[tuple[float, str, str]],
    poses: Sequence[float] | None = None,
    sensors: str | None = None,
) -> Path:
    lines = ["t,sensor,range"] + [f"{t:.3f},{s},{r}" for t, s, r in ranges]
    (folder / "ranges.csv").write_text("\n".join(lines) + "\n")
    ts = poses if poses is not None else [i * 0.1 for i in range(20)]
    (folder / "poses.csv").write_text(
        "t,x,y,yaw\n" + "".join(f"{t:.3f},{0.01 * i},0,0\n" for i, t in enumerate(ts))
    )
    if sensors is not None:
        (folder / "sensors.csv").write_text(sensors)
    return folder


def _validate(folder: Path, cfg: Config | None = None) -> ValidationReport:
    cfg = cfg or _config({"layout": "set"})
    with CsvLogReader(folder, cfg) as reader:
        return validate_log(reader, cfg)


def _one(report: ValidationReport, code: str, sensor: str = "") -> Finding:
    found = [f for f in report.findings if f.code == code and (not sensor or f.sensor == sensor)]
    assert len(found) == 1, report.format_table()
    return found[0]


def test_clean_log_is_ok_without_findings(tmp_path: Path) -> None:
    report = _validate(_write_set(tmp_path, _rows()))
    assert report.ok and report.findings == []
    assert [(s.name, s.readings, s.reasons["ok"], s.mount) for s in report.sensors] == [
        ("s0", 10, 10, "config"),
        ("s1", 10, 10, "config"),
    ]
    assert report.pose_count == 20
    assert (report.pose_first_ns, report.pose_last_ns) == (0, 1_900_000_000)
    assert "Result: OK (0 errors, 0 warnings)" in report.format_table()


def test_stamps_going_backwards(tmp_path: Path) -> None:
    rows = _rows()
    rows[6] = (0.05, "s0", "1.5")  # s0 at 0.4 s, then 0.05 s, then 0.8 s
    report = _validate(_write_set(tmp_path, rows))
    f = _one(report, "stamps_backwards")
    assert (f.severity, f.sensor) == ("ERROR", "s0")
    assert f.counts == {"backwards": 1, "max_step_back_s": pytest.approx(0.35)}
    assert not report.ok


def test_stamps_backwards_counts_what_run_drops(tmp_path: Path) -> None:
    """One jump back, then stamps that rise but stay below the earlier maximum: each of
    them is older than a stamp already seen, so validate counts them all, as run drops."""
    s0 = [0.0, 0.2, 0.4, 0.6, 0.1, 0.3, 0.5, 0.8, 1.0]  # back to 0.1, then 0.3, 0.5 (< 0.6)
    rows = [(t, "s0", f"{1.0 + 0.01 * i:.2f}") for i, t in enumerate(s0)]
    rows += [(0.05 + 0.1 * i, "s1", "1.00") for i in range(9)]
    report = _validate(_write_set(tmp_path, rows))
    f = _one(report, "stamps_backwards")
    assert f.counts == {"backwards": 3, "max_step_back_s": pytest.approx(0.5)}
    t_ns = np.array([round(t * 1e9) for t in s0], dtype=np.int64)
    dropped = StampOrder().backwards(make_range_batch(t_ns, 0, 1.0, 0.5, 0.1, 5.0))
    assert int(dropped.sum()) == 3 and dropped.tolist()[4:7] == [True, True, True]


def test_pose_gap_lists_the_largest(tmp_path: Path) -> None:
    poses = [0.0, 0.1, 0.2, 1.0, 1.1, 3.1]  # gaps of 0.8 s and 2.0 s
    report = _validate(_write_set(tmp_path, _rows(n=31), poses=poses))
    f = _one(report, "pose_gap")
    assert f.severity == "WARNING"
    assert f.counts["gaps"] == 2
    assert f.counts["largest_s"] == pytest.approx([2.0, 0.8])
    assert f.counts["at_s"] == pytest.approx([1.1, 0.2])
    assert report.ok  # warnings only
    # A looser limit finds only the 2 s gap.
    loose = _validate(tmp_path, _config({"layout": "set"}, pose_sync={"max_pose_gap_s": 1.0}))
    assert _one(loose, "pose_gap").counts["gaps"] == 1


def test_pose_stamps_backwards_is_a_warning(tmp_path: Path) -> None:
    poses = [
        0.0,
        0.2,
        0.1,
        0.3,
        0.4,
        0.5,
        0.6,
        0.7,
        0.8,
        0.9,
        1.0,
        1.1,
        1.2,
        1.3,
        1.4,
        1.5,
        1.6,
        1.7,
        1.8,
        1.9,
    ]
    report = _validate(_write_set(tmp_path, _rows(), poses=poses))
    f = _one(report, "pose_stamps_backwards")
    assert (f.severity, f.counts) == ("WARNING", {"backwards": 1})


def test_readings_outside_pose_coverage(tmp_path: Path) -> None:
    poses = [0.3 + 0.1 * i for i in range(12)]  # 0.3 .. 1.4 s; readings 0 .. 1.9 s
    report = _validate(_write_set(tmp_path, _rows(), poses=poses))
    f = _one(report, "outside_pose_coverage")
    assert f.severity == "WARNING"
    assert f.counts == {"before": 3, "after": 5, "total": 8}
    assert {s.name: s.outside_poses for s in report.sensors} == {"s0": 4, "s1": 4}


def test_time_offset_moves_readings_into_coverage(tmp_path: Path) -> None:
    poses = [0.5 + 0.1 * i for i in range(20)]
    _write_set(tmp_path, _rows(), poses=poses)
    assert _one(_validate(tmp_path), "outside_pose_coverage").counts["before"] == 5
    shifted = _config({"layout": "set"}, pose_sync={"time_offset_s": 0.5})
    assert "outside_pose_coverage" not in _validate(tmp_path, shifted).codes()


def test_poses_after_ranges_in_the_stream_still_count_coverage(tmp_path: Path) -> None:
    # Single layout: poses and ranges interleave chunk by chunk.
    lines = ["t,x,y,yaw,sensor,range"] + [
        f"{i * 0.1:.1f},0,0,0,s0,{1 + i * 0.01:.2f}" for i in range(10)
    ]
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    cfg = _config()
    with CsvLogReader(tmp_path / "log.csv", cfg) as reader:
        report = validate_log(reader, cfg)
    assert report.ok and report.findings == []


def test_reading_quality_counts(tmp_path: Path) -> None:
    rows = _rows()
    rows[0] = (0.0, "s0", "nan")
    rows[2] = (0.2, "s0", "-0.5")
    rows[4] = (0.4, "s0", "0.05")  # below r_min 0.1
    rows[6] = (0.6, "s0", "inf")
    rows[8] = (0.8, "s0", "-inf")
    rows[10] = (1.0, "s0", "5.0")  # at r_max: no echo
    rows[12] = (1.2, "s0", "4.995")  # within eps_max 0.01 of r_max
    report = _validate(_write_set(tmp_path, rows))
    assert [(f.severity, f.code, f.sensor) for f in report.findings] == [
        ("ERROR", "nan_readings", "s0"),
        ("ERROR", "negative_readings", "s0"),
        ("WARNING", "below_min_readings", "s0"),
    ]
    assert _one(report, "nan_readings").counts == {"nan": 1, "readings": 10}
    s0 = report.sensors[0]
    assert s0.reasons == {
        "ok": 3,
        "nan": 1,
        "pos_inf": 1,
        "neg_inf": 1,
        "negative": 1,
        "below_min": 1,
        "max_range": 2,
    }
    assert report.sensors[1].reasons["ok"] == 10


def test_limits_from_the_log_rows_are_used(tmp_path: Path) -> None:
    # No config limits; the per-row min_range makes 0.3 a below-min reading.
    (tmp_path / "ranges.csv").write_text("t,sensor,range,min_range\n0,a,0.3,0.5\n0.1,a,0.6,0.5\n")
    (tmp_path / "poses.csv").write_text("t,x,y,yaw\n0,0,0,0\n0.1,0,0,0\n")
    cfg = config_from_dict(
        {"input": {"csv": {"layout": "set"}}, "sensors": {"mounts": [{"name": "a"}]}}
    )
    report = _validate(tmp_path, cfg)
    assert _one(report, "below_min_readings").counts == {"below_min": 1, "readings": 2}


def test_unmounted_sensor(tmp_path: Path) -> None:
    rows = [*_rows(), (0.5, "ghost", "1.0")]
    report = _validate(_write_set(tmp_path, rows))
    f = _one(report, "unmounted_sensor")
    assert (f.severity, f.sensor, f.counts) == ("ERROR", "ghost", {"readings": 1})
    assert {s.name: s.mount for s in report.sensors}["ghost"] == "missing"
    assert not report.ok


def test_sensor_mounted_by_sensors_file_or_preset(tmp_path: Path) -> None:
    rows = [*_rows(), (0.5, "ghost", "1.0"), (0.6, "sonar_3", "1.0")]
    _write_set(tmp_path, rows, sensors="sensor,x,y,yaw\nghost,0.1,0,0\n")
    cfg = _config({"layout": "set"}, sensors={**SENSORS, "preset": "udacity-8sonar"})
    report = _validate(tmp_path, cfg)
    assert "unmounted_sensor" not in report.codes()
    assert {s.name: s.mount for s in report.sensors} == {
        "ghost": "log",
        "s0": "config",
        "s1": "config",
        "sonar_3": "preset:udacity-8sonar",
    }


def test_stuck_sensor(tmp_path: Path) -> None:
    rows = [(i * 0.01, "s0", "1.23") for i in range(60)] + [
        (0.6 + i * 0.01, "s0", f"{1 + i / 100:.2f}") for i in range(5)
    ]
    report = _validate(_write_set(tmp_path, rows, poses=[0.0, 0.4, 0.8]))
    f = _one(report, "stuck_sensor", "s0")
    assert f.severity == "WARNING"
    assert f.counts == {"longest_run": 60, "value_m": 1.23, "runs": 1, "readings_in_runs": 60}


def test_stuck_run_across_chunks_and_interleaved_sensors(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(csv_log, "CHUNK_BYTES", 40)
    rows = []
    for i in range(55):
        rows += [(i * 0.01, "s0", "2.5"), (i * 0.01, "s1", f"{1 + i / 100:.2f}")]
    report = _validate(_write_set(tmp_path, rows, poses=[0.0, 0.3, 0.6]))
    assert _one(report, "stuck_sensor").sensor == "s0"
    assert _one(report, "stuck_sensor").counts["longest_run"] == 55


def test_not_stuck_below_50_or_at_max_range(tmp_path: Path) -> None:
    rows = [(i * 0.01, "s0", "1.23") for i in range(49)]
    rows += [(0.5 + i * 0.01, "s1", "5.0") for i in range(60)]  # max range: no echo, not stuck
    rows += [(1.1 + i * 0.01, "s1", "inf") for i in range(60)]
    report = _validate(_write_set(tmp_path, rows, poses=[0.0, 0.5, 1.0, 1.5, 1.8]))
    assert "stuck_sensor" not in report.codes()
    assert report.sensors[1].reasons["max_range"] == 60


def test_no_ranges_and_no_poses(tmp_path: Path) -> None:
    (tmp_path / "ranges.csv").write_text("t,sensor,range\n")
    (tmp_path / "poses.csv").write_text("t,x,y,yaw\n")
    report = _validate(tmp_path)
    assert [(f.severity, f.code) for f in report.findings] == [
        ("ERROR", "no_poses"),
        ("ERROR", "no_ranges"),
    ]
    assert "No range sensors." in report.format_table() and "Poses: none" in report.format_table()


class _FakeReader:
    """A reader whose range stamps lag their record times (CSV has no record time)."""

    format_name = "fake"

    def __init__(self, skew_s: Sequence[float]) -> None:
        self.path = Path("fake.bag")
        self.sensor_names = ["s0"]
        self.skew_ns = np.round(np.asarray(skew_s) * 1e9).astype(np.int64)

    def info(self) -> LogInfo:
        return LogInfo(str(self.path), "fake", None, None, 0, [], ["/sonar"], "/odom")

    def batches(self, kinds: Sequence[Kind] = ALL_KINDS) -> Iterator[Batch]:
        n = self.skew_ns.shape[0]
        t = np.arange(n, dtype=np.int64) * 100_000_000
        yield PoseBatch(t, np.zeros(n), np.zeros(n), np.zeros(n), "odom", "base_link")
        ranges = 1.0 + 0.01 * np.arange(n)
        yield make_range_batch(t, 0, ranges, 0.5, 0.1, 5.0, record_t_ns=t + self.skew_ns)

    def close(self) -> None:
        pass

    def __enter__(self) -> _FakeReader:
        return self

    def __exit__(self, *exc: object) -> None:
        pass


def test_stamp_skew_max_and_median() -> None:
    skews = [0.02] * 5 + [0.3, 0.5, 0.01, 0.03, 0.025, 0.015]
    report = validate_log(_FakeReader(skews), _config())
    f = _one(report, "stamp_skew")
    assert (f.severity, f.sensor) == ("WARNING", "s0")
    assert f.counts["over_0_1s"] == 2 and f.counts["max_s"] == pytest.approx(0.5)
    assert f.counts["median_s"] == pytest.approx(0.02, rel=0.03)  # histogram resolution
    assert validate_log(_FakeReader([0.05] * 10), _config()).findings == []


def test_report_dict_is_json_ready_and_deterministic(tmp_path: Path) -> None:
    rows = _rows()
    rows[3] = (0.3, "s1", "nan")
    rows[6] = (0.05, "s0", "1.5")
    _write_set(tmp_path, rows, poses=[0.2 + 0.1 * i for i in range(5)])
    a = json.dumps(_validate(tmp_path).to_dict(), sort_keys=False)
    b = json.dumps(_validate(tmp_path).to_dict(), sort_keys=False)
    assert a == b
    d = json.loads(a)
    assert (d["ok"], d["errors"], d["warnings"]) == (False, 2, 1)
    assert [f["code"] for f in d["findings"]] == [
        "nan_readings",
        "stamps_backwards",
        "outside_pose_coverage",
    ]
    assert [s["name"] for s in d["sensors"]] == ["s0", "s1"]
    assert d["poses"] == {"count": 5, "first_ns": 200_000_000, "last_ns": 600_000_000}


def test_format_table_lists_findings_and_sensors(tmp_path: Path) -> None:
    rows = [*_rows(), (0.5, "ghost", "1.0")]
    text = _validate(_write_set(tmp_path, rows)).format_table()
    lines = text.splitlines()
    assert lines[0].startswith("Log: ") and lines[0].endswith("(csv)")
    assert any(
        ln.startswith("ERROR") and "unmounted_sensor" in ln and "ghost" in ln for ln in lines
    )
    header = next(ln for ln in lines if ln.startswith("SENSOR"))
    assert header.split() == [
        "SENSOR",
        "READINGS",
        "OK",
        "NAN",
        "POS_INF",
        "NEG_INF",
        "NEGATIVE",
        "BELOW_MIN",
        "MAX_RANGE",
        "OUTSIDE_POSES",
        "MOUNT",
    ]
    assert lines[-1] == "Result: FAILED (1 errors, 0 warnings)"


def test_udacity_sample_is_clean() -> None:
    cfg = load_config(SAMPLE / "sonarmap.toml")
    with CsvLogReader(SAMPLE, cfg) as reader:
        report = validate_log(reader, cfg)
    assert report.ok and report.findings == []
    assert [s.readings for s in report.sensors] == [413] * 8
    assert sum(s.reasons["pos_inf"] for s in report.sensors) == 1068
    assert report.pose_count == 413


def test_stamps_backwards_is_the_pipelines_rule_running_maximum(tmp_path: Path) -> None:
    """0.4 → 0.1 → 0.15: against the previous stamp only 0.1 goes back; both lie below the
    running maximum 0.4 and the pipeline drops both, so validate counts both."""
    from pipeline.stages.ingest import StampOrder

    rows = [(0.0, "s0", "1.0"), (0.2, "s0", "1.0"), (0.4, "s0", "1.1"), (0.1, "s0", "1.2"),
            (0.15, "s0", "1.3"), (0.6, "s0", "1.4")]
    folder = _write_set(tmp_path, rows)
    f = _one(_validate(folder), "stamps_backwards")
    assert f.counts == {"backwards": 2, "max_step_back_s": pytest.approx(0.3)}
    cfg = _config({"layout": "set"})
    order = StampOrder()
    with CsvLogReader(folder, cfg) as reader:
        dropped = sum(int(order.backwards(b).sum()) for b in reader.batches(("ranges",)))
    assert dropped == 2
