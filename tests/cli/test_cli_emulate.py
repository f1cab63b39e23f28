"""The ``sonarmap emulate`` command: outputs, summary, error exit codes."""

from __future__ import annotations

from pathlib import Path

import typer
from emulate_helpers import INTEL
from typer.testing import CliRunner

from cli.emulate import register


def app() -> typer.Typer:
    a = typer.Typer()

    @a.callback()
    def _root() -> None:
        """test app"""

    register(a)
    return a


def test_emulate_writes_log_map_and_trajectory(tmp_path: Path) -> None:
    out = tmp_path / "intel.mcap"
    res = CliRunner().invoke(
        app(),
        [
            "emulate",
            str(INTEL),
            "-o",
            str(out),
            "--max-scans",
            "20",
            "--fov-deg",
            "25",
            "--max-range",
            "4",
            "--resolution",
            "0.1",
            "--compression",
            "zstd",
            "--laser-max-range",
            "10",
        ],
    )
    assert res.exit_code == 0, res.output
    assert "emulated 160 readings of 8 sonars from 20 laser scans" in res.output
    assert "not emitted: sonar_8" in res.output
    assert "laser max 10 m" in res.output
    for name in ("intel.mcap", "intel.laser.yaml", "intel.laser.pgm", "intel.truth.csv"):
        assert (tmp_path / name).is_file()
    assert "resolution: 0.1\n" in (tmp_path / "intel.laser.yaml").read_text()


def test_errors_exit_1_with_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.log"
    bad.write_text("FLASER 2 1.0 1.0 0 0 0 0 0 0 1.0 host\n")
    res = CliRunner().invoke(app(), ["emulate", str(bad), "-o", str(tmp_path / "x.mcap")])
    assert res.exit_code == 1
    assert "bad.log: line 1: FLASER has 12 fields, expected 13 for 2 beams" in res.output
    assert not (tmp_path / "x.mcap").exists()
    res = CliRunner().invoke(
        app(),
        [
            "emulate",
            str(INTEL),
            "-o",
            str(tmp_path / "y.mcap"),
            "--preset",
            "nope",
            "--max-scans",
            "2",
        ],
    )
    assert res.exit_code == 1
    assert "unknown preset 'nope'" in res.output


def test_bad_format_is_a_usage_error(tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app(), ["emulate", str(INTEL), "-o", str(tmp_path / "x"), "--format", "png"]
    )
    assert res.exit_code == 2


def test_raw_odometry_flag(tmp_path: Path) -> None:
    out = tmp_path / "odo.mcap"
    args = ["emulate", str(INTEL), "-o", str(out), "--max-scans", "30", "--raw-odometry"]
    res = CliRunner().invoke(app(), args)
    assert res.exit_code == 0, res.output
    assert "note: poses: the log's raw wheel odometry" in res.output
    assert out.exists() and (tmp_path / "odo.truth.csv").exists()
    res = CliRunner().invoke(app(), [*args[:3], str(tmp_path / "b.mcap"), *args[4:],
                                     "--drift-scale", "0.03"])
    assert res.exit_code == 1
    assert "raw odometry and a drift model are exclusive" in res.output
    assert not (tmp_path / "b.mcap").exists()


def test_sonar_model_param_seed_and_firing_rate(tmp_path: Path) -> None:
    from formats import open_log
    from formats.contract import RangeBatch

    def ranges(path: Path) -> RangeBatch:
        with open_log(path) as reader:
            return RangeBatch.concat([b for b in reader.batches() if isinstance(b, RangeBatch)])

    base = ["emulate", str(INTEL), "--max-scans", "40", "-q"]
    runs = {
        "ideal": ["--sonar-model", "ideal"],
        "real": [],
        "real_again": [],
        "real_seed": ["--seed", "5"],
        "rate": ["--firing-rate", "25"],
    }
    for name, extra in runs.items():
        res = CliRunner().invoke(app(), [*base, "-o", str(tmp_path / f"{name}.mcap"), *extra])
        assert res.exit_code == 0, res.output
    r = {name: ranges(tmp_path / f"{name}.mcap") for name in runs}
    assert len(r["ideal"]) == len(r["real"]) == 320
    assert (r["real"].range_m == r["real_again"].range_m).all()  # seeded
    assert (r["real"].range_m != r["real_seed"].range_m).any()
    # The realistic sonar loses oblique walls: more max-range readings than the ideal one.
    assert (r["real"].range_m >= 5.0).sum() > (r["ideal"].range_m >= 5.0).sum()
    # 25 readings/s over the 40 scans' span, every sonar of the 16-sonar ring in turn.
    span = (r["ideal"].t_ns[-1] - r["ideal"].t_ns[0]) / 1e9
    assert abs(len(r["rate"]) - 25 * span) <= 1
    assert r["rate"].sensor_id[:17].tolist() == [*range(16), 0]
    bad = CliRunner().invoke(app(), [*base, "-o", str(tmp_path / "x.mcap"),
                                     "--sonar-param", "margin_db=-3"])
    assert bad.exit_code == 1 and "'margin_db' must be in [0, 200]" in bad.output
    assert not (tmp_path / "x.mcap").exists()
