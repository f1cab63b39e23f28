"""Issue 58, items 11, 13, 14 and 16: any file name the OS allows works in and out; names
too long fail before the work; a configured max_range bounds the grid; CSV times a map
cannot carry fail where they are read; a ROS 2 bag opens only files inside itself."""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

from typer.testing import CliRunner

from cli.app import app
from fuzz.harness import ROOT

OFFICE = ROOT / "sample_logs" / "office"


def _cli(*args: str | Path) -> tuple[int, str]:
    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res.exit_code, res.stderr


def test_file_names_of_any_bytes_work_in_and_out(tmp_path: Path) -> None:
    log = Path(os.fsdecode(os.fsencode(tmp_path) + b"/of\xff\xfeice.mcap"))
    shutil.copy(OFFICE / "office.mcap", log)
    out = Path(os.fsdecode(os.fsencode(tmp_path) + b"/out\xff"))
    code, err = _cli("run", log, "-o", out, "-q")
    assert code == 0, err
    assert (out / "features.parquet").is_file()
    assert "of\\udcff\\udcfeice.mcap" in (out / "report.md").read_text(encoding="utf-8")


def test_a_name_longer_than_name_max_fails_before_the_work(tmp_path: Path) -> None:
    out = tmp_path / ("a" * 300)
    code, err = _cli("run", OFFICE / "office.mcap", "-o", out, "-q")
    assert code == 1
    assert err == f"sonarmap: error: {out}: a path component is too long (300 bytes; at most 255)\n"
    assert list(tmp_path.iterdir()) == []


def test_names_too_long_are_one_line_errors_in_every_command(tmp_path: Path) -> None:
    long = tmp_path / ("a" * 300)
    for args in (["batch", OFFICE / "office.mcap", "-o", long], ["batch", long, "-o", tmp_path],
                 ["evaluate", tmp_path, "--truth", long], ["config", "-o", long],
                 ["info", long], ["validate", long], ["run", OFFICE / "office.mcap", "-o",
                 tmp_path / "o", "-c", long]):
        code, err = _cli(*args)
        assert code == 1
        # Local paths are checked up front; log names (which may be URLs) when opened.
        assert err.count("\n") == 1 and err.startswith(f"sonarmap: error: {long}: "), args
        assert "too long" in err, args
    assert list(tmp_path.iterdir()) == []


def _csv_log(tmp_path: Path, max_range: str) -> tuple[Path, list[str]]:
    d = tmp_path / "log"
    shutil.copytree(OFFICE / "office_csv", d)
    rows = (d / "sensors.csv").read_text().splitlines()
    (d / "sensors.csv").write_text("\n".join(
        [rows[0]] + [r.rsplit(",", 1)[0] + "," + max_range for r in rows[1:]]) + "\n")
    return d, rows[1:]


def test_a_configured_max_range_bounds_the_grid(tmp_path: Path) -> None:
    """Every sensor claims 200 m in the log; the config's mounts say 5 m and win."""
    log, rows = _csv_log(tmp_path, "200.0")
    cfg = ["[grid]", "max_cells = 2000000"]
    for r in rows:
        name, x, y, yaw = r.split(",")[:4]
        cfg += ["[[sensors.mounts]]", f'name = "{name}"', f"x = {x}", f"y = {y}",
                f"yaw_deg = {math.degrees(float(yaw))}", "max_range = 5.0"]
    (tmp_path / "c.toml").write_text("\n".join(cfg) + "\n")
    code, err = _cli("run", log, "-o", tmp_path / "o", "-c", tmp_path / "c.toml", "-q")
    assert code == 0, err
    # Without the mounts, the 200 m the log claims is too large a grid for max_cells.
    (tmp_path / "c.toml").write_text("[grid]\nmax_cells = 2000000\n")
    code, err = _cli("run", log, "-o", tmp_path / "o2", "-c", tmp_path / "c.toml", "-q")
    assert code == 1 and "exceeds grid.max_cells = 2000000" in err


def test_a_logged_max_range_below_zero_is_none_and_the_default_applies(tmp_path: Path) -> None:
    log, _ = _csv_log(tmp_path, "-5.0")
    code, err = _cli("run", log, "-o", tmp_path / "o", "-q")
    assert code == 1
    assert err == (f"sonarmap: error: {log}: cannot size the grid: no sensor reports a max"
                   " range > 0; set [grid] extent or [sensors] max_range\n")
    (tmp_path / "c.toml").write_text("[sensors]\nmax_range = 5.0\n")
    code, err = _cli("run", log, "-o", tmp_path / "o", "-c", tmp_path / "c.toml", "-q")
    assert code == 0, err


def test_negative_csv_times_fail_before_mapping_naming_the_log(tmp_path: Path) -> None:
    """Stamps map.mcap cannot carry (a log time below 0) fail at ingest, before mapping, in
    one line naming the log, never a map.mcap that does not exist."""
    d = tmp_path / "log"
    shutil.copytree(OFFICE / "office_csv", d)
    for name in ("poses.csv", "ranges.csv"):
        rows = (d / name).read_text().splitlines()
        shifted = [f"{float(r.split(',', 1)[0]) - 1700000200:.6f},{r.split(',', 1)[1]}"
                   for r in rows[1:]]
        (d / name).write_text("\n".join([rows[0], *shifted]) + "\n")
    code, err = _cli("run", d, "-o", tmp_path / "o", "-q")
    assert code == 1
    assert err == (f"sonarmap: error: {d}: the log's stamps -200.000 … -94.139 s (the map's "
                   "-94.139 s) cannot be written to MCAP: a header stamp holds -2147483648 … "
                   "2147483647 s (ROS 2's int32 seconds), a log time no negative one\n")
    assert not (tmp_path / "o").exists()


def test_ros2_metadata_naming_files_outside_the_bag_is_refused(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(OFFICE / "office_ros2", bag)
    storage = next(p.name for p in bag.iterdir() if p.name != "metadata.yaml")
    shutil.copy(bag / storage, tmp_path / storage)
    meta = (bag / "metadata.yaml").read_text()
    (bag / "inner").symlink_to(tmp_path / storage)
    for name in (f"../{storage}", str(tmp_path / storage), "inner"):
        (bag / "metadata.yaml").write_text(meta.replace(f"- {storage}", f"- {name}"))
        code, err = _cli("info", bag)
        assert code == 1
        assert err == (f"sonarmap: error: {bag / 'metadata.yaml'}: metadata names a storage "
                       f"file outside the bag: {name!r}\n")


def test_garbage_quaternions_and_absurd_mounts_say_one_line_without_warnings(
    tmp_path: Path,
) -> None:
    """numpy warnings are silenced where they arise (np.errstate), not globally; a mount at
    the edge of a float is refused in one line where it is read, not an OverflowError."""
    import warnings

    import numpy as np

    from formats.angles import yaw_from_quaternion

    big = np.array([1e308, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yaw = yaw_from_quaternion(big, big, big, big)
    assert yaw[0] == 3 * np.pi / 4 and yaw[1] == 0.0  # atan2(inf, -inf): no warning
    log, _ = _csv_log(tmp_path, "5.0")
    rows = (log / "sensors.csv").read_text().splitlines()
    rows[1] = rows[1].replace(rows[1].split(",")[1], "-1e308", 1)
    (log / "sensors.csv").write_text("\n".join(rows) + "\n")
    code, err = _cli("run", log, "-o", tmp_path / "o", "-q")
    assert code == 1
    assert err == (f"sonarmap: error: {log / 'sensors.csv'}: line 2: column 'x': -1e308 must"
                   " be in [-100, 100] m\n")
