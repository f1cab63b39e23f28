"""The udacity 8-sonar sample log reads with its sonarmap.toml and no special code."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from csvlog_helpers import read_all

from formats import open_log
from pipeline.config import load_config

SAMPLE = Path(__file__).resolve().parents[3] / "sample_logs" / "udacity-8sonar"


def test_sample_config_loads() -> None:
    cfg = load_config(SAMPLE / "sonarmap.toml")
    c = cfg.input.csv
    assert (c.layout, c.wide_ranges, c.header, c.delimiter) == ("set", True, False, "whitespace")
    assert (c.time_unit, c.length_unit, c.angle_unit, c.no_echo_value) == (
        "ms",
        "mm",
        "tenths",
        5110.0,
    )
    assert cfg.sensors.preset == "udacity-8sonar"


def test_sample_reads_with_exact_values() -> None:
    cfg = load_config(SAMPLE / "sonarmap.toml")
    r, p, mounts, names = read_all(SAMPLE, cfg)
    assert names == [f"sonar_{i}" for i in range(8)]
    assert len(r) == 413 * 8 == 3304
    assert p is not None and len(p) == 413
    assert mounts == {}  # no sensors.csv: the preset supplies the mounts
    # First row: 1686487 5110 5110 2320 2360 5110 5110 2160 1190
    assert r.t_ns[:8].tolist() == [1_686_487_000_000] * 8
    assert r.range_m[:8].tolist() == [np.inf, np.inf, 2.32, 2.36, np.inf, np.inf, 2.16, 1.19]
    assert r.sensor_id[:16].tolist() == list(range(8)) * 2
    assert r.scan_id[[0, 7, 8, 3303]].tolist() == [0, 0, 1, 412]
    # Beam limits from the preset: 20 deg, 0.17-5 m.
    assert np.allclose(r.fov_rad, math.radians(20)) and (r.min_range_m == 0.17).all()
    assert (r.max_range_m == 5.0).all()
    # Last row: 1779324 1380 1040 1650 2550 5110 3240 3050 5110
    assert r.t_ns[-1] == 1_779_324_000_000
    assert r.range_m[-8:].tolist() == [1.38, 1.04, 1.65, 2.55, np.inf, 3.24, 3.05, np.inf]
    assert int(np.isinf(r.range_m).sum()) == 1068
    # Poses: row 100 is "1708688 3401 -111 3581", the last "1779324 16842 -9437 2631".
    assert (p.t_ns[99], p.x[99], p.y[99]) == (1_708_688_000_000, 3.401, -0.111)
    assert p.yaw[99] == pytest.approx(math.radians(358.1), rel=1e-15)
    assert (p.x[-1], p.y[-1]) == (16.842, -9.437)
    assert p.yaw[-1] == pytest.approx(math.radians(263.1), rel=1e-15)


def test_sample_opens_through_open_log_with_its_config() -> None:
    cfg = load_config(SAMPLE / "sonarmap.toml")
    with open_log(SAMPLE, cfg) as reader:
        info = reader.info()
    assert info.format == "csv"
    assert [(t.name, t.count) for t in info.topics] == [
        ("measurement.txt", 413),
        ("poses.txt", 413),
    ]
    assert (info.start_ns, info.end_ns) == (1_686_487_000_000, 1_779_324_000_000)
