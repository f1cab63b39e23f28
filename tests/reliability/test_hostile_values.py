"""Hostile values in logs and configurations: non-finite numbers, absurd beam widths and
limits, odometry glitches, slow odometry, sensors that never echo. Each is refused with
one line (exit 1) or mapped correctly with the loss counted — never a traceback, an empty
map with exit 0, or a grid blown up to kilometres."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from formats.errors import ConfigError
from pipeline.config import config_from_dict

MOUNT = """\
[[sensors.mounts]]
name = "s0"
yaw_deg = 90.0
"""
SLOW = Path(__file__).resolve().parents[2] / "sample_logs" / "slow-odometry"


def _log(path: Path, n: int = 200, fov: str = "0.5", max_range: str = "5.0",
         glitch: dict[int, float] | None = None, rng: float | None = None) -> Path:
    """A single-layout CSV: the robot drives along +x at 0.5 m/s (poses 0.05 s apart), a
    wall 1.5 m to its left; ``glitch`` moves row i's pose to x = value (an odometry spike)."""
    rows = ["t,x,y,yaw,sensor,range,fov,min_range,max_range"]
    for i in range(n):
        x = (glitch or {}).get(i, 0.025 * i)
        r = 1.5 + 0.01 * (i % 3) if rng is None else rng
        rows.append(f"{0.05 * i:.3f},{x:.3f},0,0,s0,{r},{fov},0.1,{max_range}")
    path.write_text("\n".join(rows) + "\n")
    return path


def _run(tmp_path: Path, log: Path, *extra: str) -> tuple[int, str, Path]:
    cfg = tmp_path / "mount.toml"
    if not cfg.exists():
        cfg.write_text(MOUNT)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(out), "-c", str(cfg), *extra])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res.exit_code, res.stderr + res.stdout, out


# --------------------------------------------------------------------------- config values


@pytest.mark.parametrize("key", [
    "grid.resolution", "grid.margin", "scans.window_s", "mapper.c_a", "mapper.match_distance",
    "mapper.sigma_d0", "mapper.kappa_free", "mapper.eps_max", "sensors.max_range",
    "sensors.min_range", "pose_sync.max_pose_gap_s",
])
@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_config_values_are_refused_with_the_key(key: str, value: float) -> None:
    section, name = key.split(".")
    with pytest.raises(ConfigError, match=rf"'{key}' must be a finite number"):
        config_from_dict({section: {name: value}})


def test_non_finite_values_through_files_and_options(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[grid]\nresolution = inf\n")
    res = CliRunner().invoke(app, ["config", "-c", str(bad)])
    assert res.exit_code == 1 and "resolution = inf" not in res.stdout
    assert res.stderr == (f"sonarmap: error: {bad}: 'grid.resolution' must be a finite "
                          "number, got inf\n")
    log = _log(tmp_path / "log.csv")
    code, out, _ = _run(tmp_path, log, "--resolution", "inf")
    assert code == 1 and "'grid.resolution' must be a finite number" in out
    with pytest.raises(ConfigError, match=r"'mapper.seed' must be in \[0, 2\*\*63\)"):
        config_from_dict({"mapper": {"seed": -1}})
    with pytest.raises(ConfigError, match=r"'grid.extent\[2\]' must be a finite number"):
        config_from_dict({"grid": {"extent": [0.0, 0.0, math.inf, 1.0]}})


# --------------------------------------------------------------------------- beam widths


@pytest.mark.parametrize("fov", ["0", "1e-9", "-0.5", "3.1416", "1000"])
def test_absurd_beam_width_from_the_log_is_refused(tmp_path: Path, fov: str) -> None:
    log = _log(tmp_path / "log.csv", fov=fov)
    code, out, dest = _run(tmp_path, log, "-q")
    assert code == 1
    assert out.startswith(f"sonarmap: error: {log}: sensor s0: beam width (fov) ")
    assert "set fov_deg for it in [[sensors.mounts]]" in out and len(out.splitlines()) == 1
    assert not dest.exists()
    res = CliRunner().invoke(app, ["validate", str(log), "-c", str(tmp_path / "mount.toml"),
                                   "--json"])
    assert res.exit_code == 1
    codes = [(f["code"], f["sensor"]) for f in json.loads(res.stdout)["findings"]]
    assert ("bad_beam", "s0") in codes


def test_max_range_not_above_min_range_from_the_log_is_refused(tmp_path: Path) -> None:
    log = _log(tmp_path / "log.csv", max_range="0.05")
    code, out, _ = _run(tmp_path, log, "-q")
    assert code == 1 and "sensor s0: max_range 0.05 m is not above min_range 0.1 m" in out


def test_config_refuses_absurd_beam_widths() -> None:
    for fov in (0.1, 180.0, -3.0):
        with pytest.raises(ConfigError, match=r"fov_deg' must be in \[0.5, 180\) deg \(0 = from the log\)"):
            config_from_dict({"sensors": {"mounts": [{"name": "a", "fov_deg": fov}]}})


# --------------------------------------------------------------------------- pose outliers


def _grid_size(out: Path) -> tuple[int, int]:
    head = (out / "map.pgm").read_bytes()[:32].split()
    return int(head[1]), int(head[2])


@pytest.mark.parametrize("where", ["spike", "pair", "step_at_end"])
def test_pose_outliers_do_not_blow_up_the_grid(tmp_path: Path, where: str) -> None:
    # A spike to 2 km and back (one pose, or two); a 600 m jump for the last 2 of 400
    # poses (0.5 %).
    glitch = {
        "spike": {100: 2000.0},
        "pair": {100: 2000.0, 101: 2000.0},
        "step_at_end": {i: 600.0 + 0.025 * i for i in (398, 399)},
    }[where]
    log = _log(tmp_path / "log.csv", n=400, glitch=glitch)
    code, out, dest = _run(tmp_path, log, "-q")
    assert code == 0, out
    w, h = _grid_size(dest)
    assert w * h < 400_000  # ~10 m of path plus 5 m reach, not 600 m or 2 km
    m = json.loads((dest / "metrics.json").read_text())
    dropped, counts = m["dropped"], m["counts"]
    if where == "spike":  # dropped from the track: the reading at its stamp keeps a pose
        assert (counts["poses_spikes"], counts["poses_outliers"]) == (1, 0)
        assert (dropped["pose_jump"], dropped["outside_grid"]) == (0, 0)
    elif where == "pair":
        assert (counts["poses_spikes"], counts["poses_outliers"]) == (0, 2)
        assert dropped["pose_jump"] == 0  # the readings at the glitch's own stamps ...
        assert dropped["outside_grid"] == 2  # ... are placed there, outside the grid
    else:
        assert (counts["poses_spikes"], counts["poses_outliers"]) == (0, 2)
        assert dropped["outside_grid"] == 2
    assert counts["readings_mapped"] >= 390
    res = CliRunner().invoke(app, ["validate", str(log), "-c", str(tmp_path / "mount.toml"),
                                   "--json"])
    jump = [f for f in json.loads(res.stdout)["findings"] if f["code"] == "pose_jump"]
    assert len(jump) == 1 and jump[0]["severity"] == "WARNING"
    assert (jump[0]["counts"]["jumps"], jump[0]["counts"]["spikes"]) == {
        "spike": (2, 1), "pair": (2, 0), "step_at_end": (1, 0)}[where]


def test_grid_beyond_max_cells_is_refused_with_the_size_and_the_fix(tmp_path: Path) -> None:
    log = _log(tmp_path / "log.csv")
    (tmp_path / "mount.toml").write_text(MOUNT + "\n[grid]\nextent = [0.0, 0.0, 500.0, 500.0]\n")
    code, out, _ = _run(tmp_path, log, "-q")
    assert code == 1
    assert ("grid of 10000x10000 = 100000000 cells (500 x 500 m) exceeds grid.max_cells = "
            "40000000") in out


# --------------------------------------------------------------------------- slow odometry


def test_slow_odometry_sample_maps_with_the_automatic_pose_gap(tmp_path: Path) -> None:
    out = tmp_path / "slow"
    res = CliRunner().invoke(app, ["run", str(SLOW), "-o", str(out)])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    assert m["run"]["median_pose_interval_s"] == pytest.approx(0.9)
    assert m["run"]["max_pose_gap_s"] == pytest.approx(2.7)
    assert m["dropped"]["in_pose_gap"] == 0
    n, total = m["counts"]["readings_mapped"], m["counts"]["readings"]
    assert total == 599 and n > 400
    assert res.stdout.startswith(f"used {n} of 599 readings; {m['counts']['features']} features")


def test_a_run_that_maps_nothing_is_an_error_naming_cause_and_fix(tmp_path: Path) -> None:
    cfg = tmp_path / "gap.toml"
    cfg.write_text("[pose_sync]\nmax_pose_gap_s = 0.5\n")
    out = tmp_path / "slow"
    res = CliRunner().invoke(app, ["run", str(SLOW), "-o", str(out), "-c", str(cfg), "-q"])
    assert res.exit_code == 1 and not out.exists()
    assert res.stderr == (
        f"sonarmap: error: {SLOW}: only 0 of 599 readings could be mapped (at least 1% "
        "needed); 594 were dropped as in_pose_gap: they fall in gaps between poses longer "
        "than [pose_sync] max_pose_gap_s = 0.5 s while the poses are 0.9 s apart (median): "
        "raise max_pose_gap_s, or set it to 0 for the automatic limit\n"
    )
    res = CliRunner().invoke(app, ["validate", str(SLOW), "-c", str(cfg), "--json"])
    assert res.exit_code == 1
    gap = next(f for f in json.loads(res.stdout)["findings"] if f["code"] == "pose_gap")
    assert gap["severity"] == "ERROR" and gap["counts"]["readings_dropped"] == 594
    assert "raise [pose_sync] max_pose_gap_s to keep them" in gap["message"]


def test_all_readings_at_max_range_is_an_error_naming_the_key(tmp_path: Path) -> None:
    log = _log(tmp_path / "log.csv", rng=5.0)
    code, out, dest = _run(tmp_path, log, "-q")
    assert code == 1 and not dest.exists()
    assert "only 0 of 200 readings could be mapped" in out
    assert "200 were dropped as max_range" in out and "clear_on_max_range = true" in out
    (tmp_path / "mount.toml").write_text(MOUNT + "\n[mapper]\nclear_on_max_range = true\n")
    code, out, _ = _run(tmp_path, log, "-q")
    assert code == 0, out


# --------------------------------------------------------------------------- fuzz.values


def test_every_numeric_config_key_with_every_hostile_number() -> None:
    from fuzz.values import HOSTILE, check_config, numeric_keys

    keys = numeric_keys()
    assert ("grid", "resolution") in keys and ("mapper", "seed") in keys
    defects = [o.detail for s, k in keys for v in HOSTILE
               if (o := check_config(s, k, v)).status == "defect"]
    assert defects == []


def test_hostile_logs_map_or_are_refused_in_one_line(tmp_path: Path) -> None:
    import random

    from fuzz.values import check_log

    rnd = random.Random(12)
    outcomes = [check_log(tmp_path, rnd, i) for i in range(12)]
    assert [o.detail for o in outcomes if o.status == "defect"] == []
    assert {o.status for o in outcomes} == {"ok", "rejected"}
