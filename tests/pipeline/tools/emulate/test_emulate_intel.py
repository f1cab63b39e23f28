"""End to end on the real Intel Research Lab log: emulate → write → read back."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from emulate_helpers import INTEL, REPO

from formats import open_log
from formats.carmen import read_carmen
from formats.contract import MountBatch, PoseBatch, RangeBatch
from formats.errors import FormatError, OutputError
from formats.writers.nav2_map import load_nav2_map
from pipeline.tools.emulate import EmulateOptions, load_laser_log, run_emulation

SAMPLE = REPO / "sample_logs" / "intel-lab"


def read_back(path: Path) -> tuple[RangeBatch, int, MountBatch]:
    ranges: list[RangeBatch] = []
    poses = 0
    mounts = MountBatch("", {})
    with open_log(path) as reader:
        for b in reader.batches():
            if isinstance(b, RangeBatch):
                ranges.append(b)
            elif isinstance(b, PoseBatch):
                poses += len(b)
            else:
                mounts = b
    return RangeBatch.concat(ranges), poses, mounts


def test_intel_log_copy_counts() -> None:
    log = read_carmen(INTEL)
    assert len(log.laser) == 910
    assert log.laser.ranges.shape == (910, 180)
    assert len(log.odom) == 14541
    assert log.skipped == {"NEFF": 910}
    # 4 scans of the corrected log have stamps going backwards: emulation sorts them.
    laser = load_laser_log(INTEL)
    assert bool(np.all(np.diff(laser.t_ns) > 0))
    assert any("4 scans had stamps going backwards" in n for n in laser.notes)


def test_first_50_scans_emulate_write_and_read_back(tmp_path: Path) -> None:
    opts = EmulateOptions(sonar_model="ideal", max_scans=50)
    res = run_emulation(INTEL, tmp_path / "intel.mcap", "mcap", options=opts)
    assert [p.name for p in res.paths] == [
        "intel.mcap",
        "intel.laser.yaml",
        "intel.laser.pgm",
        "intel.truth.csv",
    ]
    assert (res.scans, res.readings) == (50, 400)
    ranges, poses, mounts = read_back(tmp_path / "intel.mcap")
    assert len(ranges) == 400
    assert poses == 50
    assert sorted(mounts.mounts) == [f"sonar_{i}" for i in range(8)]
    assert mounts.mounts["sonar_0"].yaw == pytest.approx(math.pi / 2)
    r = ranges.range_m
    assert np.all((r > 0.1) & (r <= 5.0) | np.isneginf(r))
    np.testing.assert_allclose(ranges.fov_rad, math.radians(30), rtol=1e-6)  # float32 field
    # The readings are the emulated ones, float32-rounded, in time order.
    laser = load_laser_log(INTEL, max_scans=50)
    assert ranges.t_ns.tolist() == np.repeat(laser.t_ns, 8).tolist()
    truth = (tmp_path / "intel.truth.csv").read_text().splitlines()
    assert truth[0] == "t,x,y,yaw" and len(truth) == 51
    assert truth[1] == "32.906800000,0.600266,-0.0320327,-0.3546649999999998"
    lmap = load_nav2_map(tmp_path / "intel.laser.yaml")
    assert lmap.grid.resolution == 0.05
    assert int((lmap.classes == 1).sum()) > 500 and int((lmap.classes == 0).sum()) > 5000
    # The same input gives the same bytes; existing outputs are refused.
    again = tmp_path / "again"
    again.mkdir()
    run_emulation(INTEL, again / "intel.mcap", "mcap", options=opts)
    for name in ("intel.mcap", "intel.laser.pgm", "intel.laser.yaml", "intel.truth.csv"):
        assert (again / name).read_bytes() == (tmp_path / name).read_bytes()
    with pytest.raises(OutputError, match=r"intel\.mcap: exists already, not overwriting"):
        run_emulation(INTEL, tmp_path / "intel.mcap", "mcap", options=opts)


def test_csv_output_reads_back(tmp_path: Path) -> None:
    run_emulation(INTEL, tmp_path / "intel.csv", "csv", options=EmulateOptions(sonar_model="ideal", max_scans=10))
    ranges, poses, _ = read_back(tmp_path / "intel.csv")
    assert len(ranges) == 80
    assert poses == 10


def test_committed_sample_matches_its_readme() -> None:
    ranges, poses, mounts = read_back(SAMPLE / "intel.mcap")
    assert (len(ranges), poses, len(mounts)) == (7280, 910, 8)
    assert len((SAMPLE / "intel.truth.csv").read_text().splitlines()) == 911
    lmap = load_nav2_map(SAMPLE / "intel.laser.yaml")
    assert lmap.grid.shape == (741, 794)


def test_unreadable_inputs(tmp_path: Path) -> None:
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01 not a log")
    with pytest.raises(FormatError, match=r"junk\.bin: neither a CARMEN log"):
        load_laser_log(junk)
    csv = tmp_path / "ranges.csv"
    csv.write_text("t,x,y,yaw,sensor,range\n0,0,0,0,s,1\n")
    with pytest.raises(FormatError, match=r"a csv log has no laser scans"):
        load_laser_log(csv)
    with pytest.raises(FormatError, match=r"no such file or directory"):
        load_laser_log(tmp_path / "missing.log")
